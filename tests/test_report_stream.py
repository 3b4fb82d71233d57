"""The report in one streaming pass: `summarise_file` gives what the whole-run report gave (checked against the
reference below, the report as it was before it streamed) on every sample log's `datmo run` output and on edge
cases, for any block size; and what it holds is counted: one block of messages, O(1) numbers per track."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli import report
from datmo_cli.base.errors import GeometryError, MissingChannelError
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types, vocabulary
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.passes import pipeline

pytestmark = pytest.mark.cli

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"
TRACK = cdr.element_dtype(types.TRACK)
LANDMARK = cdr.element_dtype(types.LANDMARK)


# ---------------------------------------------------------------- reference: the whole-run report, slow and obvious


def ref_track_rows(h: report.TrackHistory, t0_ns: int) -> list[dict]:
    rows = []
    for g, tid in enumerate(h.ids.tolist()):
        a, b = int(h.starts[g]), int(h.starts[g + 1])
        s = h.states[a:b]
        conf = s["status"] == vocabulary.STATUS_CONFIRMED
        x, y, speed = h.x[a:b][conf], h.y[a:b][conf], h.speed[a:b][conf]
        occ = s["occluded"].astype(bool)
        t_first, t_last = (h.stamps[a] - t0_ns) / 1e9, (h.stamps[b - 1] - t0_ns) / 1e9
        rows.append(
            {
                "id": tid,
                "class": vocabulary.CLASS_NAMES.get(int(s["classification"][-1]), "unknown"),
                "mobility": vocabulary.MOBILITY_NAMES.get(int(s["mobility"][-1]), "undefined"),
                "first_s": round(float(t_first), 3),
                "last_s": round(float(t_last), 3),
                "lifetime_s": round(float(t_last - t_first), 3),
                "scans": b - a,
                "distance_m": round(float(np.hypot(np.diff(x), np.diff(y)).sum()), 3),
                "mean_speed_mps": round(float(speed.mean()), 3) if len(speed) else 0.0,
                "max_speed_mps": round(float(speed.max()), 3) if len(speed) else 0.0,
                "occlusions": int(occ[0]) + int(np.sum(occ[1:] & ~occ[:-1])),
                "occluded_scans": int(occ.sum()),
                "confirmed": bool(conf.any()),
                "x_m": round(float(x[-1]), 3) if len(x) and np.isfinite(x[-1]) else None,
                "y_m": round(float(y[-1]), 3) if len(y) and np.isfinite(y[-1]) else None,
            }
        )
    return rows


def ref_run_facts(data: report.RunData) -> dict:
    s = data.scan_stamps
    dt = np.diff(s) / 1e9
    period = float(np.median(dt)) if len(dt) else 0.0
    dropped = int(np.sum(np.maximum(np.round(dt / period) - 1, 0))) if period > 0 else 0
    meta = data.metadata.get("datmo", {})
    params = {}
    for k, v in data.metadata.get("datmo.params", {}).items():
        try:
            params[k] = json.loads(v)
        except ValueError:
            params[k] = v
    return {
        "file": data.name,
        "duration_s": round(float((s[-1] - s[0]) / 1e9), 3) if len(s) else 0.0,
        "scans": int(len(s)),
        "rate_hz": round(1 / period, 3) if period > 0 else None,
        "beams": int(data.n_beams),
        "dropped_scans": dropped,
        "start_ns": int(s[0]) if len(s) else 0,
        "version": meta.get("version"),
        "command": meta.get("command_line") or meta.get("command"),
        "parameters": params,
    }


def ref_feature_facts(features: report.Decoded | None) -> dict | None:
    if features is None:
        return None
    out = {"scans": len(features)}
    for name in ("lines", "circles", "blobs"):
        c = features.counts(name) if name in features.offsets else np.zeros(len(features), np.int64)
        out[name] = {
            "total": int(c.sum()),
            "per_scan": round(float(c.mean()), 3) if len(c) else 0.0,
            "max_per_scan": int(c.max()) if len(c) else 0,
        }
    return out


def ref_landmark_rows(landmarks: report.Decoded | None, t0_ns: int) -> list[dict] | None:
    if landmarks is None:
        return None
    if not len(landmarks) or "landmarks" not in landmarks.items:
        return []
    off = landmarks.offsets["landmarks"]

    def secs(t: np.ndarray) -> float:
        return round((int(t["sec"]) * 1_000_000_000 + int(t["nanosec"]) - t0_ns) / 1e9, 3)

    return [
        {
            "id": int(lm["id"]),
            "type": vocabulary.LANDMARK_NAMES.get(int(lm["type"]), str(int(lm["type"]))),
            "x_m": round(float(lm["x"]), 3),
            "y_m": round(float(lm["y"]), 3),
            "size_m": round(float(lm["size"]), 3),
            "first_seen_s": secs(lm["first_seen"]),
            "last_seen_s": secs(lm["last_seen"]),
            "scans": int(lm["count"]),
            "frame": landmarks.frame_id,
        }
        for lm in landmarks.items["landmarks"][off[-2] : off[-1]]
    ]


def reference(data: report.RunData) -> report.RunSummary:
    """The report as `summarise` made it from a whole decoded run before it streamed."""
    facts = ref_run_facts(data)
    t0 = facts["start_ns"]
    hist = report.track_history(data.tracks)
    tracks = ref_track_rows(hist, t0)
    return report.RunSummary(
        facts,
        ref_feature_facts(data.features),
        ref_landmark_rows(data.landmarks, t0),
        report.class_rows(tracks),
        tracks,
        "world" if hist.world else "sensor",
    )


def text(s: report.RunSummary) -> str:
    """Every field of a summary, exactly (floats by repr, NaN as null), in order."""
    return report.to_json(vars(s))


def assert_same_everywhere(path: Path) -> report.RunSummary:
    """summarise_file at several block sizes, summarise(RunData) and the reference agree exactly."""
    want = text(reference(pipeline.read_run_data(path)))
    got = report.summarise_file(path)
    assert text(got) == want
    assert text(report.summarise(pipeline.read_run_data(path))) == want
    for block in (1, 7, 100):
        assert text(report.summarise_file(path, block=block)) == want, block
    return got


# ------------------------------------------------------------------------------- every sample log's datmo run output


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("runs")
    paths = {}
    for src in sorted(SAMPLES.glob("*.mcap")):
        paths[src.stem] = out / src.name
        pipeline.process_file(src, paths[src.stem])
    return paths


SAMPLE_NAMES = sorted(p.stem for p in SAMPLES.glob("*.mcap"))


@pytest.mark.parametrize("name", SAMPLE_NAMES)
def test_sample_run_outputs_report_as_before(outputs, name):
    got = assert_same_everywhere(outputs[name])
    assert got.tracks and got.features and got.landmarks is not None
    assert got.run["scans"] == len(pipeline.read_run_data(outputs[name]).scan_stamps)


def test_sample_outputs_cover_both_frames(outputs):
    frames = {report.summarise_file(p).frame for p in outputs.values()}
    assert frames == {"world", "sensor"}


def test_report_command_streams_without_a_plot(outputs, monkeypatch):
    path = outputs["hall"]
    want = CliRunner().invoke(cli, ["report", str(path), "--format", "json"]).output

    def whole(*args, **kwargs):
        raise AssertionError("datmo report decoded the whole run")

    monkeypatch.setattr(pipeline, "read_run_data", whole)
    result = CliRunner().invoke(cli, ["report", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert result.output == want
    assert json.loads(want)["files"][0]["run"]["scans"] == 300


def test_run_final_report_streams_without_plots(outputs, monkeypatch, capsys):
    from datmo_cli.commands import run as run_command

    path = outputs["patrol"]
    want = report.render([reference(pipeline.read_run_data(path))], "json", top=None, sort="lifetime")

    def whole(*args, **kwargs):
        raise AssertionError("datmo run's report decoded the whole run")

    monkeypatch.setattr(pipeline, "read_run_data", whole)
    run_command._report([path], [], "json", None, "lifetime")
    assert capsys.readouterr().out == want


# ------------------------------------------------------------------------------------------------------ edge cases

GEOM = ScanGeometry(-np.pi / 2, np.pi / 180, 181, 0.0, 8.0, 0.0, 0.2, "laser")


def track_states(k: int, world: bool, rng: np.random.Generator) -> np.ndarray:
    """A few tracks after scan k: ids come and go, statuses and occlusion change, positions drift."""
    ids = [i for i in range(1, 9) if (k // (i + 2)) % 3 != 2]
    t = np.zeros(len(ids), TRACK)
    t["id"] = ids
    t["status"] = rng.choice([0, 1, 1, 1, 2], len(ids))
    t["occluded"] = rng.random(len(ids)) < 0.2
    t["classification"] = rng.integers(0, 4, len(ids))
    t["mobility"] = rng.integers(0, 3, len(ids))
    t["x"], t["y"] = np.array(ids) + 0.05 * k + rng.normal(0, 0.02, len(ids)), rng.normal(0, 1, len(ids))
    t["vx"], t["vy"] = rng.normal(0, 1, (2, len(ids)))
    t["world_x"], t["world_y"], t["world_vx"], t["world_vy"] = (
        (t["x"] + 10, t["y"] - 3, t["vx"], t["vy"]) if world else (np.nan,) * 4
    )
    return t


def write_log(
    path: Path,
    stamps: np.ndarray,
    *,
    tracks: str = "some",
    features: bool = True,
    landmarks: bool = True,
    world: bool = False,
    geometry_change_at: int | None = None,
) -> Path:
    """A processed log with one scan per stamp; `tracks`: "some", "none" (a channel of empty messages) or
    "absent"; features and landmarks channels optional."""
    rng = np.random.default_rng(len(stamps))
    other = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("run", {"gate_m": 1.5}, command_line="datmo run x")) as w:
        for k, s in enumerate(stamps.tolist()):
            g = other if geometry_change_at is not None and k >= geometry_change_at else GEOM
            w.write_scans(ScanRun(np.array([s], np.int64), np.full((1, g.n_beams), 5.0, np.float32), g))
            if features:
                f = {
                    n: np.zeros((k * m) % 4, cdr.element_dtype(t))
                    for n, m, t in (("lines", 1, types.LINE), ("circles", 3, types.CIRCLE), ("blobs", 2, types.BLOB))
                }
                w.write(
                    mcapio.TOPIC_FEATURES,
                    types.FEATURES,
                    s,
                    cdr.encode(types.FEATURES, {"stamp_ns": s, "frame_id": "laser", **f}),
                )
            if landmarks:
                db = np.zeros(k % 3, LANDMARK)
                db["id"], db["type"], db["x"], db["count"] = np.arange(len(db)), 4, 1.5, k
                db["first_seen"]["sec"], db["last_seen"]["sec"] = s // 1_000_000_000, s // 1_000_000_000
                w.write(
                    mcapio.TOPIC_LANDMARKS,
                    types.LANDMARKS,
                    s,
                    cdr.encode(
                        types.LANDMARKS, {"stamp_ns": s, "frame_id": "odom" if k == 0 else "laser", "landmarks": db}
                    ),
                )
            if tracks != "absent":
                t = track_states(k, world, rng) if tracks == "some" else np.zeros(0, TRACK)
                w.write(
                    mcapio.TOPIC_TRACKS,
                    types.TRACKS,
                    s,
                    cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": "laser", "tracks": t}),
                )
    return path


T0 = 1_700_000_000_000_000_000


def regular(n: int, period_ns: int = 100_000_000) -> np.ndarray:
    return T0 + np.arange(n, dtype=np.int64) * period_ns


def jitter(n: int) -> np.ndarray:
    """Up to ±9 ms of jitter (10 µs steps) on n stamps: many distinct periods, distinct middle ones."""
    return np.random.default_rng(n).integers(-900, 900, n) * 10_000


EDGES = {
    "no tracks at all": lambda p: write_log(p, regular(40), tracks="none"),
    "no features channel": lambda p: write_log(p, regular(40), features=False),
    "no landmarks channel": lambda p: write_log(p, regular(40), landmarks=False),
    "no features nor landmarks": lambda p: write_log(p, regular(40), features=False, landmarks=False),
    "one scan": lambda p: write_log(p, regular(1)),
    "two scans": lambda p: write_log(p, regular(2)),
    "world frame": lambda p: write_log(p, regular(60), world=True),
    "dropped scans, even count": lambda p: write_log(p, np.delete(regular(61), [5, 6, 7, 30])),
    "dropped scans, odd count": lambda p: write_log(p, np.delete(regular(62), [5, 40])),
    "jittered stamps, odd count": lambda p: write_log(p, regular(80) + jitter(80)),
    "jittered stamps, even count": lambda p: write_log(p, regular(81) + jitter(81)),
    "repeated stamps": lambda p: write_log(p, np.repeat(regular(20), 2)),
    "two runs interleaved (the writer orders them by time)": lambda p: write_log(
        p, np.r_[regular(20), regular(10) + 5_000_000]
    ),
}


@pytest.mark.parametrize("case", list(EDGES))
def test_edge_cases_report_as_before(tmp_path, case):
    got = assert_same_everywhere(EDGES[case](tmp_path / "edge.mcap"))
    if case == "no tracks at all":
        assert got.tracks == [] and got.classes == [] and got.frame == "sensor"
    if case.startswith("no features"):
        assert got.features is None
    if "landmarks" in case:
        assert got.landmarks is None
    if case == "one scan":
        r = got.run
        assert (r["scans"], r["rate_hz"], r["dropped_scans"], r["duration_s"]) == (1, None, 0, 0)
    if case.startswith("dropped"):
        assert got.run["dropped_scans"] == (4 if "even" in case else 2) and got.run["rate_hz"] == 10.0
    if case == "world frame":
        assert got.frame == "world"


def test_track_stamps_out_of_file_order(tmp_path):
    """Header stamps that go back in the file (log times that are not the stamps; not a log datmo writes):
    within a block the report sorts them as the whole-run report did; across blocks it says so."""
    path = tmp_path / "shuffled.mcap"
    stamps = regular(40)
    header = np.random.default_rng(3).permutation(stamps)
    rng = np.random.default_rng(4)
    with mcapio.LogWriter(path) as w:
        w.write_scans(ScanRun(stamps, np.full((40, GEOM.n_beams), 5.0, np.float32), GEOM))
        for k, (s, h) in enumerate(zip(stamps.tolist(), header.tolist(), strict=True)):
            w.write(
                mcapio.TOPIC_TRACKS,
                types.TRACKS,
                s,
                cdr.encode(types.TRACKS, {"stamp_ns": h, "frame_id": "laser", "tracks": track_states(k, False, rng)}),
            )
    want = text(reference(pipeline.read_run_data(path)))
    assert text(report.summarise_file(path)) == want
    assert text(report.summarise(pipeline.read_run_data(path))) == want
    with pytest.warns(UserWarning, match="track state.* after a later-stamped state of their track"):
        report.summarise_file(path, block=7)


def test_missing_channels_and_a_changing_geometry_are_refused_as_before(tmp_path):
    no_tracks = write_log(tmp_path / "a.mcap", regular(5), tracks="absent")
    with pytest.raises(MissingChannelError, match="no messages on /datmo/tracks; run datmo track"):
        report.summarise_file(no_tracks)
    changing = write_log(tmp_path / "b.mcap", regular(30), geometry_change_at=20)
    with pytest.raises(GeometryError, match="scan geometry changes"):
        pipeline.read_run_data(changing)
    for block in (7, 1000):
        with pytest.raises(GeometryError, match="scan geometry changes"):
            report.summarise_file(changing, block=block)
    # a missing channel is named before a changing geometry, as RunData.from_log orders them
    both = write_log(tmp_path / "c.mcap", regular(30), tracks="absent", geometry_change_at=20)
    with pytest.raises(MissingChannelError):
        report.summarise_file(both, block=7)


# ------------------------------------------------------------------------- random tracks, split in random blocks


@st.composite
def track_runs(draw) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Random track states: (per-state stamps, states, block cuts)."""
    n_msgs = draw(st.integers(1, 40))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    world = draw(st.sampled_from(["finite", "nan", "some nan"]))
    gaps = rng.choice([0, 1, 1, 2, 7], n_msgs)  # repeated stamps too
    msg_stamps = T0 + np.cumsum(gaps).astype(np.int64) * 50_000_000
    if draw(st.booleans()):  # messages out of stamp order (not a log datmo writes)
        msg_stamps = rng.permutation(msg_stamps)
    stamps, states = [], []
    for s in msg_stamps.tolist():
        n = int(rng.integers(0, 6))
        t = np.zeros(n, TRACK)
        t["id"] = rng.choice(np.arange(1, 9), n, replace=False) * 1000
        t["status"], t["occluded"] = rng.integers(0, 3, n), rng.random(n) < 0.3
        t["classification"], t["mobility"] = rng.integers(0, 4, n), rng.integers(0, 3, n)
        for f in ("x", "y", "vx", "vy", "world_x", "world_y", "world_vx", "world_vy"):
            t[f] = rng.normal(0, 5, n)
        if world == "nan" or (world == "some nan" and rng.random() < 0.1):
            t["world_x"] = np.nan
        stamps += [s] * n
        states.append(t)
    states = np.concatenate(states)
    cuts = sorted(draw(st.lists(st.integers(0, len(states)), max_size=5)))
    return np.array(stamps, np.int64), states, cuts


@settings(max_examples=200, deadline=None)
@given(track_runs())
def test_track_figures_equal_the_reference_however_the_states_are_split(run):
    stamps, states, cuts = run
    # the reference's Decoded: one message per state (track_history only needs each state's stamp)
    decoded = report.Decoded(
        stamps, "laser", items={"tracks": states}, offsets={"tracks": np.arange(len(stamps) + 1, dtype=np.int64)}
    )
    hist = report.track_history(decoded)
    want = report.to_json(ref_track_rows(hist, T0))
    whole = report.TrackStats()
    whole.add(stamps, states)
    assert report.to_json(whole.rows(T0)) == want and whole.late == 0 and whole.world == hist.world
    acc = report.TrackStats()
    for a, b in zip([0, *cuts], [*cuts, len(states)], strict=True):
        acc.add(stamps[a:b], states[a:b])
    assert len(acc) == len(np.unique(states["id"])) and acc.world == hist.world
    if np.all(np.diff(stamps) >= 0):
        assert acc.late == 0
    if acc.late == 0:  # else states come after later ones of their track, blocks before: taken in file order
        assert report.to_json(acc.rows(T0)) == want


# ------------------------------------------------------------------------------------- what is held, by counting


def held_numbers(acc: report.RunAccumulator) -> dict[str, int]:
    """Elements of every array the accumulator keeps, by name."""
    out = {}
    for owner, prefix in ((acc, ""), (acc.tracks, "tracks."), (acc.scans, "scans.")):
        for name, v in vars(owner).items():
            if isinstance(v, np.ndarray):
                out[prefix + name] = v.size
            elif isinstance(v, list | dict | bytes):
                out[prefix + name] = len(v)
    return out


def test_what_is_held_does_not_grow_with_the_log(tmp_path, monkeypatch):
    decoded_at_once = []
    decode_channel = report.decode_channel

    def counting(msgtype, payloads, *first):
        decoded_at_once.append(len(payloads))
        return decode_channel(msgtype, payloads, *first)

    monkeypatch.setattr(report.stream, "decode_channel", counting)  # where stream_run looks it up
    held = {}
    for n in (300, 3000):
        path = write_log(tmp_path / f"long{n}.mcap", np.delete(regular(n), [7, 8, 100]))
        decoded_at_once.clear()
        acc = report.stream_run(path, block=100)
        assert acc.peak_messages == 100  # one block of payloads (and their decoded forms) at a time
        assert max(decoded_at_once) <= 100
        assert len(acc.tracks) == 8 and all(
            v.shape[-1] == 8 for v in vars(acc.tracks).values() if isinstance(v, np.ndarray)
        )
        assert len(acc.scans.periods) == 3  # the regular period, two and three periods across the drops
        held[n] = held_numbers(acc)
        assert report.to_json(vars(acc.summary())) == report.to_json(vars(reference(pipeline.read_run_data(path))))
    assert held[300] == held[3000]
