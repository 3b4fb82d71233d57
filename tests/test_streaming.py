"""Commands stream: a log is read, processed and written block by block, so what is held at once does not
depend on the log's length, and the results do not depend on the block size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.passes import streaming
from datmo_cli.passes.pipeline import process_file
from datmo_cli.passes.stage_files import features_file, segment_file, track_file
from datmo_cli.perception.egomotion import EGO_SAMPLE_SCANS

pytestmark = pytest.mark.cli

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"
DECODE, DRAIN = mcapio.decode_scan_block, mcapio.LogWriter.drain


def channels(path: Path) -> dict[str, tuple[list[int], list[bytes]]]:
    log = mcapio.read_log(path, topics=None)
    return {t: log.messages[t] for t in log.topics()}


@pytest.mark.parametrize("log", ["hall.mcap", "patrol.mcap"])
def test_run_gives_the_same_messages_whatever_the_block_size(tmp_path: Path, log: str) -> None:
    whole, small = tmp_path / "whole.mcap", tmp_path / "small.mcap"
    assert process_file(SAMPLES / log, whole) == 300
    assert process_file(SAMPLES / log, small, block_scans=37) == 300
    a, b = channels(whole), channels(small)
    assert a.keys() == b.keys() and mcapio.TOPIC_TRACKS in a and mcapio.TOPIC_LANDMARKS in a
    for topic in a:
        assert a[topic] == b[topic], topic


def test_stage_commands_give_the_same_messages_whatever_the_block_size(tmp_path: Path) -> None:
    src = SAMPLES / "corridor.mcap"
    segment_file(src, tmp_path / "s1.mcap", block_scans=1000)
    segment_file(src, tmp_path / "s2.mcap", block_scans=50)
    assert channels(tmp_path / "s1.mcap") == channels(tmp_path / "s2.mcap")
    features_file(tmp_path / "s1.mcap", tmp_path / "f1.mcap", block_scans=1000)
    features_file(tmp_path / "s1.mcap", tmp_path / "f2.mcap", block_scans=64)
    assert channels(tmp_path / "f1.mcap") == channels(tmp_path / "f2.mcap")
    track_file(tmp_path / "f1.mcap", tmp_path / "t1.mcap", block_scans=1000)
    track_file(tmp_path / "f1.mcap", tmp_path / "t2.mcap", block_scans=23)
    assert channels(tmp_path / "t1.mcap") == channels(tmp_path / "t2.mcap")
    # the stages one after another write what datmo run writes in one pass
    process_file(src, tmp_path / "run.mcap", block_scans=77)
    run, staged = channels(tmp_path / "run.mcap"), channels(tmp_path / "t1.mcap")
    for topic in (mcapio.TOPIC_SEGMENTS, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS, mcapio.TOPIC_TRACKS):
        assert run[topic] == staged[topic], topic


def long_log(path: Path, n: int) -> Path:
    """A synthetic log of n scans (181 beams, 5 Hz): a room 6 m across with a blob walking to and fro."""
    g = ScanGeometry(
        angle_min=-np.pi / 2,
        angle_increment=np.pi / 180,
        n_beams=181,
        range_min=0.05,
        range_max=30.0,
        scan_time=0.2,
        frame_id="laser",
    )
    angles = g.angles()
    room = np.minimum(3.0 / np.maximum(np.abs(np.sin(angles)), 1e-3), 5.0 / np.maximum(np.cos(angles), 1e-3))
    k = np.arange(n)
    ranges = np.tile(room, (n, 1)).astype(np.float32)
    beam = (60 + (np.abs((k % 100) - 50))).astype(np.int64)  # the walker's bearing sweeps 50 beams and back
    for d in range(-2, 3):
        ranges[k, beam + d] = 2.0 + 0.02 * abs(d)
    run = ScanRun(1_700_000_000_000_000_000 + k.astype(np.int64) * 200_000_000, ranges, g)
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
    return path


class Held:
    """Counts, while patched in, the most scans one block holds and the most messages waiting in the writer."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.block = self.buffered = self.blocks = 0
        self.sizes: list[int] = []
        decode, drain = DECODE, DRAIN
        held = self

        def counting_decode(path, payloads, *args, **kw):
            held.block = max(held.block, len(payloads))
            held.blocks += 1
            held.sizes.append(len(payloads))
            return decode(path, payloads, *args, **kw)

        def counting_drain(writer) -> None:
            held.buffered = max(held.buffered, sum(len(b[2]) for b in writer._buffer))
            drain(writer)

        monkeypatch.setattr(mcapio, "decode_scan_block", counting_decode)
        monkeypatch.setattr(mcapio.LogWriter, "drain", counting_drain)


def test_what_a_run_holds_does_not_grow_with_the_log(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    held = {}
    logs = {n: long_log(tmp_path / f"long{n}.mcap", n) for n in (600, 2400)}
    for n, src in logs.items():
        counter = Held(monkeypatch)
        assert process_file(src, tmp_path / f"out{n}.mcap", block_scans=200) == n
        held[n] = counter
        out = mcapio.summary(tmp_path / f"out{n}.mcap").topics()
        assert out[mcapio.TOPIC_TRACKS].count == n and out[mcapio.TOPIC_SCAN].count == n
    # the log's first scans (at most EGO_SAMPLE_SCANS) to see whether the scanner moves (it does not), its first
    # scan for the geometry the tracker is built with, then the run
    assert held[600].blocks == 2 + 3 and held[2400].blocks == 2 + 12
    assert held[600].sizes[:2] == [600, 1] and held[2400].sizes[:2] == [EGO_SAMPLE_SCANS, 1]
    # then one block at a time: 200 scans, and the scan plus 4 derived messages of each waiting to be written
    # (segments, features, landmarks, tracks: no markers unless asked)
    assert max(held[600].sizes[2:]) == max(held[2400].sizes[2:]) == 200
    assert held[600].buffered == held[2400].buffered == 200 * 5


def test_a_geometry_change_between_blocks_is_refused(tmp_path: Path) -> None:
    a = long_log(tmp_path / "a.mcap", 30)
    run = mcapio.read_run(a)
    wide = ScanRun(
        run.stamps + 10_000_000_000,
        np.pad(run.ranges, ((0, 0), (0, 1)), constant_values=4.0),
        ScanGeometry(**{**run.geometry.__dict__, "n_beams": run.geometry.n_beams + 1}),
    )
    both = tmp_path / "both.mcap"
    with mcapio.LogWriter(both) as w:
        w.write_scans(run)
        w.write_scans(wide)
    from datmo_cli.base.errors import GeometryError

    with pytest.raises(GeometryError, match="changes at scan 30"):
        segment_file(both, tmp_path / "out.mcap", block_scans=30)
    assert not (tmp_path / "out.mcap").exists()
    assert not list(tmp_path.glob(".out.mcap.*"))


def test_blocks_end_before_the_scan_that_would_overflow_them(tmp_path: Path) -> None:
    src = long_log(tmp_path / "a.mcap", 10)
    stream = streaming.LogStream(src)
    sizes = [len(b.run) for b in stream.blocks(4, copy={mcapio.TOPIC_SCAN})]
    assert sizes == [4, 4, 2]
    firsts = [b.first for b in stream.blocks(4)]
    assert firsts == [0, 4, 8]


def test_markers_only_when_asked_and_nothing_else_changes(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    src = SAMPLES / "corridor.mcap"
    runner = CliRunner()
    done = runner.invoke(cli, ["run", str(src), "-o", str(tmp_path / "a"), "--no-report", "-j", "1"])
    assert done.exit_code == 0, done.output
    process_file(src, tmp_path / "full.mcap", markers=True)
    lean, full = channels(tmp_path / "a" / "corridor.mcap"), channels(tmp_path / "full.mcap")
    markers = {mcapio.TOPIC_MARKERS_FEATURES, mcapio.TOPIC_MARKERS_TRACKS}
    assert markers <= full.keys() and not markers & lean.keys()
    assert {t: full[t] for t in full if t not in markers} == lean
    for command, drawn in (("features", {mcapio.TOPIC_MARKERS_FEATURES}), ("track", markers)):
        out, fat = tmp_path / f"{command}.mcap", tmp_path / f"{command}-markers.mcap"
        for path, extra in ((out, []), (fat, ["--markers"])):
            done = runner.invoke(cli, [command, str(src), "-o", str(path), *extra])
            assert done.exit_code == 0, done.output
        assert not markers & channels(out).keys() and mcapio.TOPIC_FEATURES in channels(out)
        assert markers & channels(fat).keys() == drawn


def test_covariance_only_when_asked_and_nothing_else_changes(tmp_path: Path) -> None:
    from datmo_cli.logs import cdr, types

    src = SAMPLES / "corridor.mcap"
    process_file(src, tmp_path / "lean.mcap")
    process_file(src, tmp_path / "cov.mcap", covariance=True)
    lean, cov = channels(tmp_path / "lean.mcap"), channels(tmp_path / "cov.mcap")
    assert {t: v for t, v in lean.items() if t != mcapio.TOPIC_TRACKS} == {
        t: v for t, v in cov.items() if t != mcapio.TOPIC_TRACKS
    }
    a = np.concatenate([cdr.decode(types.TRACKS, p)["tracks"] for p in lean[mcapio.TOPIC_TRACKS][1]])
    b = np.concatenate([cdr.decode(types.TRACKS, p)["tracks"] for p in cov[mcapio.TOPIC_TRACKS][1]])
    assert len(a) == len(b) > 0
    assert np.isnan(a["covariance"]).all() and np.isfinite(b["covariance"]).all()
    rest = [n for n in a.dtype.names if n != "covariance"]
    from numpy.lib.recfunctions import repack_fields

    assert repack_fields(a[rest]).tobytes() == repack_fields(b[rest]).tobytes()
    assert (tmp_path / "lean.mcap").stat().st_size < (tmp_path / "cov.mcap").stat().st_size


def test_an_input_fetched_from_an_object_store_is_named_by_its_url_in_provenance(tmp_path: Path) -> None:
    fsspec = pytest.importorskip("fsspec")
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    mem = fsspec.filesystem("memory")
    mem.pipe("/datmo-prov/in/corridor.mcap", (SAMPLES / "corridor.mcap").read_bytes())
    try:
        done = CliRunner().invoke(
            cli, ["run", "memory://datmo-prov/in/corridor.mcap", "-o", str(tmp_path / "out"), "--no-report", "-j", "1"]
        )
        assert done.exit_code == 0, done.output
        meta = mcapio.summary(tmp_path / "out" / "corridor.mcap").metadata["datmo.inputs"]
        assert list(meta) == ["memory://datmo-prov/in/corridor.mcap"]
        assert meta["memory://datmo-prov/in/corridor.mcap"] == mcapio.sha256_of(SAMPLES / "corridor.mcap")
    finally:
        mem.rm("/datmo-prov", recursive=True)
    local = tmp_path / "local.mcap"
    process_file(SAMPLES / "corridor.mcap", local)
    assert list(mcapio.summary(local).metadata["datmo.inputs"]) == [str(SAMPLES / "corridor.mcap")]
