"""`datmo import` and `datmo simulate` stream: the same messages as the whole-run commands they replaced
(digests in import_digests.json, taken before the change) for any block size, and memory that holds a block
whatever the input's length (counted, not timed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import shared_path
from hypothesis import given, settings
from hypothesis import strategies as st
from import_cases import (
    DIGESTS,
    SIMULATE_CASES,
    digest,
    import_digest,
    odom_line,
    rawlaser,
    shared_inputs,
    simulate_digest,
    synthetic_inputs,
)
from test_import_carmen import flaser, write
from test_import_rosbag import ODOM, SCAN, _odom, _scan, write_ros1

import datmo_cli.logs.importers as importers
import datmo_cli.logs.ordered as ordered
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.logs.importers import open_import, write_import
from datmo_cli.logs.importers.carmen_conventions import StampCheck
from datmo_cli.logs.ordered import OrderedSink

pytestmark = pytest.mark.cli

REFERENCE = json.loads(DIGESTS.read_text())
SHARED = sorted(k for k in REFERENCE if k.startswith(("carmen/", "legtracker/", "killian")))
SYNTHETIC = sorted(k for k in REFERENCE if k not in SHARED and not k.startswith("simulate/"))
# (scans per block, messages in the time-order window): the default, and small ones that cut every log
SIZES = [(None, None), (3, 5), (1, 1)]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return synthetic_inputs(tmp_path_factory.mktemp("inputs"))


def _sizes(monkeypatch, block, window) -> None:
    if block is not None:
        monkeypatch.setattr(importers, "IMPORT_BLOCK", block)
    if window is not None:
        monkeypatch.setattr(ordered, "WINDOW", window)


def _check(name: str, src: Path, extra: list[str], out: Path) -> None:
    code, text, dig = import_digest(src, extra, out)
    ref = REFERENCE[name]
    assert (code, text) == (ref["exit_code"], ref["output"])
    assert dig == ref["digest"], f"{name}: messages differ from the whole-run import"
    assert not list(out.parent.glob(".datmo-import-*")), "the spool is left behind"


@pytest.mark.parametrize(("block", "window"), SIZES)
@pytest.mark.parametrize("name", SYNTHETIC)
def test_import_equals_the_whole_run_import(name, block, window, synthetic, tmp_path, monkeypatch):
    _sizes(monkeypatch, block, window)
    src, extra = synthetic[name]
    _check(name, src, extra, tmp_path / "out.mcap")


@pytest.mark.shared
@pytest.mark.parametrize("name", SHARED)
def test_import_of_shared_logs_equals_the_whole_run_import(name, tmp_path):
    src, extra = shared_inputs(shared_path())[name]
    _check(name, src, extra, tmp_path / "out.mcap")


@pytest.mark.shared
@pytest.mark.parametrize(
    "name",
    [
        "carmen/freiburg-079-corrected.log.gz",
        "killian",
        "legtracker/demo_stationary_simple_environment.bag",
        "legtracker/negative_2.bag/right_scan",
    ],
)
def test_import_of_shared_logs_in_small_blocks(name, tmp_path, monkeypatch):
    _sizes(monkeypatch, 97, 150)
    src, extra = shared_inputs(shared_path())[name]
    _check(name, src, extra, tmp_path / "out.mcap")


# ------------------------------------------------------------------------------------------- simulate


@pytest.mark.parametrize("name", sorted(SIMULATE_CASES))
def test_simulate_equals_the_whole_run_simulation(name, tmp_path):
    code, text, dig = simulate_digest(SIMULATE_CASES[name], tmp_path / "sim.mcap")
    ref = REFERENCE[f"simulate/{name}"]
    assert (code, text, dig) == (ref["exit_code"], ref["output"], ref["digest"])


def test_simulate_of_a_moving_sensor_over_several_blocks_equals_the_whole_run(tmp_path):
    """Against the whole-run writer datmo simulate had (simulate_scene, then every channel at once)."""
    from datmo_cli.logs import transforms, types
    from datmo_cli.sim.scene import load_scene
    from datmo_cli.sim.simulate import CHUNK, simulate_scene

    args = ["--scene", "patrol", "--duration", "60", "--rate", "10", "--seed", "3"]
    out = tmp_path / "new.mcap"
    assert CliRunner().invoke(cli, ["simulate", *args, "-o", str(out)]).exit_code == 0
    scene = load_scene("patrol")
    res = simulate_scene(scene, seed=3, duration=60.0, rate=10.0)
    assert len(res.run) > CHUNK and res.odometry is not None
    ref = tmp_path / "ref.mcap"
    params = {
        "scene": "patrol",
        "seed": 3,
        "duration": 60.0,
        "rate": 10.0,
        "people": None,
        "angle": 180,
        "resolution": 0.5,
        "range": 8,
        "units": "mm",
        "noise": 0.01,
    }
    with mcapio.LogWriter(ref, provenance=mcapio.Provenance("simulate", params, [])) as writer:
        writer.add_metadata("datmo.scene", {"name": scene.name, "source": Path(scene.source).name, "toml": scene.text})
        writer.write_scans(res.run)
        writer.write_odometry(res.odometry)
        writer.write_many(mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH, res.run.stamps, res.ground_truth_payloads())
        t0 = int(res.run.stamps[0])  # the transforms: base_link -> laser (the identity), odom -> base_link a pose
        writer.write_transforms(
            [t0], [transforms.mount_tf(t0, "base_link", "laser", transforms.LaserPose())], static=True
        )
        writer.write_transforms(res.odometry.stamps, transforms.odometry_tf(res.odometry))
    assert digest(out, out) == digest(ref, ref)


# ------------------------------------------------------------------------------- what memory holds


def _carmen_log(tmp_path: Path, lines: int) -> Path:
    """A RAWLASER log with ODOM poses between the scans: `lines` lines, half of each."""
    text = []
    for i in range(lines // 2):
        text.append(odom_line(0.01 * i, 10.0 + 0.1 * i - 0.02))
        text.append(rawlaser([1.0 + 0.1 * ((i + k) % 9) for k in range(31)], 10.0 + 0.1 * i))
    return write(tmp_path, f"long{lines}.log.gz", text, gz=True)


def _held(src: Path, out: Path, **kw) -> importers.ImportStats:
    stream = open_import(src, block_scans=100, spool_dir=out.parent, **kw)
    return write_import(stream, out, window=300)


def test_carmen_import_holds_one_block_whatever_the_length(tmp_path):
    short = _held(_carmen_log(tmp_path, 5_000), tmp_path / "short.mcap")
    long = _held(_carmen_log(tmp_path, 20_000), tmp_path / "long.mcap")
    assert (short.scans, long.scans) == (2_500, 10_000)
    assert (short.poses, long.poses) == (2_500, 10_000)
    assert short.peak_scans == long.peak_scans == 100
    assert short.peak_messages == long.peak_messages <= 2 * 300 + 3 * 100  # a block: scans, poses and their /tf
    assert short.late == long.late == 0
    assert not list(tmp_path.glob(".datmo-import-*"))


def test_carmen_import_memory_does_not_grow_with_the_log(tmp_path):
    """Python's traced allocations, not just what the importer counts: the same peak for 4x the lines."""
    import tracemalloc

    peaks = []
    for lines in (4_000, 16_000):
        src = _carmen_log(tmp_path, lines)
        open_import(src, spool_dir=tmp_path).close()  # modules imported, caches filled
        tracemalloc.start()
        try:
            _held(src, tmp_path / f"{lines}.mcap")
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
    assert peaks[1] < 1.25 * peaks[0], peaks


def test_carmen_parse_spools_every_scan(tmp_path):
    from datmo_cli.logs.importers.carmen_parse import parse_lines

    lines = [flaser([1.0] * 20, 5.0 + i) for i in range(3000)] + [odom_line(1.0, 5.0 + i) for i in range(50)]
    parse = parse_lines(lines, spool=tmp_path)
    s = parse.streams["FLASER"]
    assert s.count == 3000 and (s.ranges, s.remissions, s.stamps_s, s.poses, parse.odom.rows) == ([],) * 5
    assert (tmp_path / "FLASER.ranges").stat().st_size == 3000 * 20 * 8


def _bag(tmp_path: Path, scans: int) -> Path:
    msgs = []
    for i in range(scans):
        t = 1_000_000_000 + i * 20_000_000
        msgs.append(("/scan", SCAN, t, lambda s, t=t: _scan(s, t, 16, "laser", 2.0, True)))
        msgs.append(("/odom", ODOM, t + 3, lambda s, t=t, i=i: _odom(s, t + 3, 0.01 * i, 0.0)))
    return write_ros1(tmp_path / f"long{scans}.bag", msgs)


def test_bag_import_holds_one_block_whatever_the_length(tmp_path):
    short = _held(_bag(tmp_path, 1_000), tmp_path / "short.mcap")
    long = _held(_bag(tmp_path, 4_000), tmp_path / "long.mcap")
    assert (short.scans, long.scans) == (1_000, 4_000)
    assert short.peak_scans == long.peak_scans == 100
    assert short.peak_messages == long.peak_messages <= 2 * 300 + 3 * 100  # a block: scans, poses and their /tf


def test_simulate_holds_one_block_whatever_the_duration(tmp_path, monkeypatch):
    from datmo_cli.sim import simulate

    held = []
    chunks = simulate.Simulation.chunks

    def counted(self, size=simulate.CHUNK):
        for c in chunks(self, 64):
            held.append(len(c.stamps))
            yield c

    monkeypatch.setattr(simulate.Simulation, "chunks", counted)
    drained = []
    drain = mcapio.LogWriter.drain

    def counted_drain(self):
        drained.append(sum(len(b[0]) for b in self._buffer))
        drain(self)

    monkeypatch.setattr(mcapio.LogWriter, "drain", counted_drain)
    peaks = []
    for duration in ("20", "80"):
        held.clear()
        drained.clear()
        args = ["simulate", "--scene", "hall", "--duration", duration, "-o", str(tmp_path / f"{duration}.mcap")]
        assert CliRunner().invoke(cli, args).exit_code == 0
        peaks.append((max(held), max(drained)))
    assert peaks[0] == peaks[1] == (64, 2 * 64)  # a block's scans; its scans and ground truth (no /odom)


# ------------------------------------------------------------------------------------ order and stamps


def test_ordered_sink_writes_the_whole_run_order_when_messages_come_within_the_window(tmp_path):
    rng = np.random.default_rng(4)
    n = 3000
    stamps = np.sort(rng.integers(0, 500, n)) * 1000
    cids = rng.integers(1, 3, n)
    arrival = np.argsort(np.arange(n) + rng.uniform(0, 40, n), kind="stable")  # each at most ~40 late
    paths = {}
    for name, window in (("whole", None), ("window", 64)):
        out = tmp_path / f"{name}.mcap"
        with mcapio.LogWriter(out) as writer:
            ids = {1: writer.channel("/a", "std_msgs/msg/String"), 2: writer.channel("/b", "std_msgs/msg/String")}
            if window is None:
                for i in arrival.tolist():
                    writer.write_ids(ids[cids[i]], [stamps[i]], [f"{i}".encode()])
            else:
                sink = OrderedSink(writer, window)
                for i in arrival.tolist():
                    sink.add(ids[cids[i]], [stamps[i]], [f"{i}".encode()])
                    sink.flush()
                sink.close()
                assert sink.late == 0 and sink.peak <= 2 * window + 1
        paths[name] = out
    assert digest(paths["whole"], paths["whole"]) == digest(paths["window"], paths["window"])


def test_messages_later_than_the_window_are_written_with_a_warning(tmp_path, monkeypatch):
    msgs = []
    for i in range(40):
        t = 1_000_000_000 + i * 20_000_000
        msgs.append(("/scan", SCAN, t, lambda s, t=t: _scan(s, t, 8, "laser", 2.0)))
        # odometry whose header stamps lag 30 scans behind the log times
        msgs.append(("/odom", ODOM, t, lambda s, t=t, i=i: _odom(s, t - 30 * 20_000_000, 0.01 * i, 0.0)))
    src = write_ros1(tmp_path / "late.bag", msgs)
    _sizes(monkeypatch, 4, 8)
    out = tmp_path / "late.mcap"
    result = CliRunner().invoke(cli, ["import", str(src), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "messages came after later ones beyond a window of 8; written out of time order" in result.output
    log = mcapio.read_log(out, topics=None)
    assert len(log.messages["/scan"][1]) == 40 and len(log.messages["/odom"][1]) == 40


def test_an_interrupted_import_leaves_no_spool(tmp_path):
    src = write(tmp_path, "a.log", [flaser([1.0] * 10, 1.0 + i) for i in range(5)])
    out = tmp_path / "out.mcap"
    out.write_bytes(b"taken")
    stream = open_import(src, spool_dir=tmp_path)
    assert list(tmp_path.glob(".datmo-import-*"))
    with pytest.raises(Exception, match="exists"):
        write_import(stream, out)
    assert not list(tmp_path.glob(".datmo-import-*")) and out.read_bytes() == b"taken"


def _stamps_ns_whole(t: np.ndarray) -> tuple[np.ndarray, str | None]:
    """The whole-run stamp rule: a stamp that is not finite (the first: or negative), or that does not follow
    the last usable one, is bad; none bad: kept; at most 5 % bad and the first good: each bad one set 1 ms after
    the one before; else all synthesised at 1 s per scan. The note names the first 5 bad scans."""
    t = np.asarray(t, np.float64)
    n = len(t)
    usable = np.isfinite(t) & (t < 9.2e9)
    if n:
        usable[0] &= t[0] >= 0
    prev, bad, invalid, which = None, 0, 0, []
    for i, v in enumerate(t.tolist()):
        if not usable[i]:
            invalid += 1
        elif prev is not None and v <= prev:
            bad += 1
        else:
            prev = v
            continue
        which.append(i)
    first_bad = bool(n) and not usable[0]
    scans = (
        f"scan{'s' if len(which[:5]) > 1 else ''} {', '.join(map(str, which[:5]))}{', ...' if len(which) > 5 else ''}"
    )
    what = " and ".join(
        ([f"{bad} stamps go backwards or repeat"] if bad else [])
        + ([f"{invalid} {'is' if invalid == 1 else 'are'} not a number or out of range"] if invalid else [])
    )
    if n and not first_bad and bad + invalid == 0:
        return np.round(t * 1e9).astype(np.int64), None
    if n and not first_bad and bad + invalid <= 0.05 * n:
        ns = np.round(np.where(usable, t, 0.0) * 1e9).astype(np.int64)
        for i in range(1, n):
            if ns[i] <= ns[i - 1] or not usable[i]:
                ns[i] = ns[i - 1] + 1_000_000
        return ns, f"{what}; each set 1 ms after the one before ({scans})"
    t0 = float(t[0]) if n and np.isfinite(t[0]) and 0 <= t[0] < 9.2e9 else 0.0
    synth = int(round(t0 * 1e9)) + np.arange(n, dtype=np.int64) * 1_000_000_000
    if not invalid:
        return synth, f"not increasing ({len(np.unique(t))} distinct of {n}); synthesised at 1 s per scan"
    why = "the first stamp is one" if first_bad else "more than 5 % of the stamps are bad"
    return synth, f"{what} ({scans}) and {why}; all {n} synthesised at 1 s per scan"


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(st.one_of(st.floats(0.001, 2.0), st.sampled_from([0.0, -0.5, -3.0])), min_size=1, max_size=120),
    start=st.sampled_from([0.0, 1.13486e9, 100.25, -1.0, float("nan")]),
    holes=st.lists(st.integers(0, 119), max_size=4),
    block=st.integers(1, 50),
)
def test_stamp_check_block_by_block_equals_the_whole_run_rule(steps, start, holes, block):
    t = start + np.concatenate([[0.0], np.cumsum(steps[1:])])
    t[[h for h in holes if h < len(t)]] = np.nan  # a few stamps that are not numbers
    check = StampCheck()
    for v in t.tolist():
        check.add(v)
    note = check.note(lambda: t)
    ns = np.concatenate([check.apply(t[a : a + block]) for a in range(0, len(t), block)])
    want_ns, want_note = _stamps_ns_whole(t)
    assert note == want_note
    np.testing.assert_array_equal(ns, want_ns)


def test_a_spool_that_cannot_be_made_is_a_one_line_error(tmp_path):
    from datmo_cli.base.errors import DatmoError

    src = write(tmp_path, "a.log", [flaser([1.0] * 10, 1.0 + i) for i in range(5)])
    with pytest.raises(DatmoError, match="cannot make a temporary folder for the parsed scans"):
        open_import(src, spool_dir=src)  # a file, not a folder
