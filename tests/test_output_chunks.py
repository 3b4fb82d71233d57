"""Outputs in windows of log time (streaming.CHUNK_SECONDS), a channel's messages after another's in a window:
the same messages as the interleaved writing of before, in one stream of chunks in time order, readable in
time order by mcap's own reader, and read back by `LogStream.blocks` into the same blocks whatever the
reader's and the writer's block sizes."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from run_cases import digests

from datmo_cli.base.errors import InputError
from datmo_cli.logs import mcapio
from datmo_cli.passes import streaming
from datmo_cli.passes.pipeline import process_file
from datmo_cli.passes.stage_files import features_file

pytestmark = pytest.mark.cli

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


def interleaved(monkeypatch, src: Path, out: Path, **kw) -> None:
    """`process_file` with every channel in one chunk stream, in time order (how outputs were written before)."""
    real = mcapio.LogWriter

    def writer(*args, **kwargs):
        kwargs["grouped"] = False
        return real(*args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(mcapio, "LogWriter", writer)
        process_file(src, out, force=True, **kw)


@pytest.mark.parametrize("log", ["patrol.mcap", "csail-excerpt.mcap"])
def test_grouped_chunks_hold_the_messages_of_the_interleaved_writing(tmp_path, monkeypatch, log) -> None:
    grouped, mixed = tmp_path / "grouped.mcap", tmp_path / "mixed.mcap"
    process_file(SAMPLES / log, grouped, force=True, markers=True, block_scans=50)
    interleaved(monkeypatch, SAMPLES / log, mixed, markers=True, block_scans=50)
    a, b = mcapio.read_log(grouped, topics=None), mcapio.read_log(mixed, topics=None)
    assert a.messages == b.messages  # every channel's messages, stamps and bytes, in file order
    assert digests(grouped) == digests(mixed)
    with open(grouped, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.id: c.topic for c in summary.channels.values()}
        indexes = sorted(summary.chunk_indexes, key=lambda i: i.chunk_start_offset)
        starts = [i.message_start_time for i in indexes]
        assert starts == sorted(starts)  # one stream of chunks, in time order (mcap_chunks)
        assert len({c for i in summary.chunk_indexes for c in i.message_index_offsets}) == len(topics)
        stamps = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert stamps == sorted(stamps) and len(stamps) == sum(len(s) for s, _ in a.messages.values())


def file_order_lag(path: Path) -> tuple[int, list[int]]:
    """(the most log time, ns, by which a message comes after a later one when `path` is read from start to end
    without its summary, as a pipe or a cut download reads it; the stamps in that order)."""
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    latest, worst, stamps = None, 0, []
    with open(path, "rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, Message):
                stamps.append(record.log_time)
                latest = record.log_time if latest is None else max(latest, record.log_time)
                worst = max(worst, latest - record.log_time)
    return worst, stamps


@pytest.mark.parametrize("log", ["patrol.mcap", "csail-excerpt.mcap"])
def test_an_output_read_without_its_index_is_in_time_order_within_chunk_seconds(tmp_path, log) -> None:
    """Read from start to end without the summary (a pipe, a cut download), no message of `datmo run`'s output
    comes more than CHUNK_SECONDS of log time after a later one, across chunks too (small ones here), and mcap's
    indexed reader still gives them all in time order."""
    out = tmp_path / "out.mcap"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(streaming, "CHUNK_BYTES", 64 << 10)
        process_file(SAMPLES / log, out, force=True, markers=True, block_scans=50)
    worst, stamps = file_order_lag(out)
    assert worst < streaming.CHUNK_SECONDS * 1e9
    assert stamps != sorted(stamps) or log == "csail-excerpt.mcap"  # a channel after another: within the bound
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) > 1
        indexed = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert indexed == sorted(stamps)


@pytest.mark.slow
def test_a_ten_minute_output_read_in_file_order_is_within_chunk_seconds_of_time_order(tmp_path) -> None:
    """A default `datmo run` output of a 10-minute simulated log (patrol, 5 Hz, 3,000 scans, 22 MB of messages),
    read without its index: every message within CHUNK_SECONDS of time order, and every message there."""
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    log, out = tmp_path / "patrol.mcap", tmp_path / "out.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "patrol", "--duration", "600", "-o", str(log)])
    assert result.exit_code == 0, result.output
    process_file(log, out, force=True)
    worst, stamps = file_order_lag(out)
    assert 0 < worst < streaming.CHUNK_SECONDS * 1e9  # out of order (a channel after another), within bounds
    assert stamps[-1] - stamps[0] > 599e9
    with open(out, "rb") as f:
        reader = make_reader(f)
        indexed = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert indexed == sorted(stamps)


def test_rosbags_reads_a_grouped_output_message_for_message_in_time_order(tmp_path) -> None:
    """ROS 2's Python tooling (rosbags' AnyReader, as `datmo import` and rosbag2 users read MCAP) gets every
    message of a chunk-per-channel output, with mcap's bytes and stamps, in time order across many chunks.
    (Foxglove's reader, @mcap/core's McapIndexedReader, was checked by hand the same way: CHANGELOG.md.)"""
    from rosbags.highlevel import AnyReader

    out = tmp_path / "out.mcap"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(streaming, "CHUNK_BYTES", 64 << 10)  # many chunks
        process_file(SAMPLES / "patrol.mcap", out, force=True, markers=True, block_scans=25)
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) > len(summary.channels)
        ref = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=True)]
    with AnyReader([out]) as bag:
        got = [(c.topic, t, bytes(d)) for c, t, d in bag.messages(connections=bag.connections)]
    assert [t for _, t, _ in got] == sorted(t for _, t, _ in got)
    assert sorted(got) == sorted(ref) and len(got) == len(ref)


def test_blocks_are_the_same_for_any_reader_and_writer_block_size(tmp_path) -> None:
    feats = tmp_path / "features.mcap"
    features_file(SAMPLES / "patrol.mcap", feats, force=True, block_scans=100)
    log = mcapio.read_log(feats, topics=None)
    stream = streaming.LogStream(feats)
    copy = set(log.topics())
    seen = []
    for size in (1, 7, 1024):
        blocks = list(stream.blocks(size, aligned=(mcapio.TOPIC_FEATURES,), copy=copy))
        assert all(len(b.run) == size for b in blocks[:-1])
        for b in blocks:
            assert len(b.aligned[mcapio.TOPIC_FEATURES]) == len(b.run)
            end = blocks[blocks.index(b) + 1].run.stamps[0] if b is not blocks[-1] else None
            for stamps, _ in b.copies.values():
                assert end is None or all(t <= end for t in stamps)  # nothing of a later block's stretch
        whole = {
            t: (
                [s for b in blocks for s in b.copies.get(t, ([], []))[0]],
                [p for b in blocks for p in b.copies.get(t, ([], []))[1]],
            )
            for t in copy
        }
        assert whole == {t: log.messages[t] for t in copy}
        assert [p for b in blocks for p in b.aligned[mcapio.TOPIC_FEATURES]] == log.messages[mcapio.TOPIC_FEATURES][1]
        seen.append([s for b in blocks for s in b.run.stamps.tolist()])
    assert seen[0] == seen[1] == seen[2]


def test_a_missing_aligned_message_is_refused(tmp_path) -> None:
    feats = tmp_path / "features.mcap"
    features_file(SAMPLES / "patrol.mcap", feats, force=True)
    log = mcapio.read_log(feats, topics=None)
    cut = tmp_path / "cut.mcap"
    with mcapio.LogWriter(cut, grouped=True, span=2) as writer:
        ids = writer.copy_channels(log)
        for topic, (stamps, payloads) in log.messages.items():
            if topic == mcapio.TOPIC_FEATURES:
                stamps, payloads = stamps[:10] + stamps[11:], payloads[:10] + payloads[11:]
            writer.write_ids(ids[topic], stamps, payloads)
    with pytest.raises(InputError, match="messages on"):
        list(streaming.LogStream(cut).blocks(7, aligned=(mcapio.TOPIC_FEATURES,)))
