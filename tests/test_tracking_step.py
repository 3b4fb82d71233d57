"""The compiled tracking step (datmo_cli/tracking/_step.py) against the reference tracker of
tests/reference_tracking.py (today's rules as numpy statements): every phase on the reference's own state
scan by scan (lockstep), whole runs on every sample log (learned legs and the paper's rule, with and without
odometry), and random scenes. Equal means: the same tracks, ids, classes, mobility, status and occlusion,
and float64 state within 1e-9 (Track elements byte for byte). The assignment solver gives scipy's answer
ties included (test_tracking_assign.py), so no tie is broken differently."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.synthetic_features import features_from_lists
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import ScanGeometry
from datmo_cli.passes.stages import iter_run_features, leg_threshold_of, track_run
from datmo_cli.tracking import (
    _association,
    _background,
    _classify,
    _life_cycle,
    _people,
    _scan_measurements,
    _step,
    state,
)
from datmo_cli.tracking.bundles import ScanMeasurements
from datmo_cli.tracking.markers import track_markers
from datmo_cli.tracking.measurements import Measurements
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.tracker import _COMPAT, _COMPAT_LEARNED, _REACQUIRE, _REACQUIRE_LEARNED, TRACK_DTYPE, Tracker
from tests.conftest import SAMPLE_LOGS
from tests.reference_tracking import (
    ReferenceTracker,
    kalman_predict,
    kind_groups,
    moved,
    reference_measurements,
    with_candidates,
)

pytestmark = pytest.mark.unit

P = TrackingParams()
THR = leg_threshold_of("default")  # the shipped leg model's threshold, which datmo track takes
PRM = P.kernel_vector(THR)
LOGS = sorted(p.name for p in SAMPLE_LOGS.glob("*.mcap"))
EXACT = ("id", "age", "hits", "misses", "classification", "mobility", "status", "occluded")


@cache
def sample(name: str, leg_model: str) -> tuple:
    """(run, features, odometry, poses) of a sample log as `datmo track` tracks it."""
    from datmo_cli.passes.pipeline import estimated_odometry
    from datmo_cli.perception.features import extract_run
    from datmo_cli.perception.params import FeatureParams

    log = mcapio.read_log(SAMPLE_LOGS / name, topics=None)
    run = mcapio.run_from_log(log)
    odometry, _ = estimated_odometry(run, mcapio.odometry_from_log(log), P.ego_motion)
    feats = list(
        iter_run_features(extract_run(run, params=FeatureParams().replace(leg_model=leg_model), odometry=odometry))
    )
    poses = odometry.at(run.stamps) if odometry is not None and len(odometry) else None
    return run, feats, odometry, poses


# ------------------------------------------------------------------------------------ state conversion
def to_table(ref: ReferenceTracker, t0: int) -> np.ndarray:
    """The reference's tracks as a track table (times in ns since t0)."""
    t = ref.tracks
    K, T = len(t), P.tail_length
    tab = np.zeros((max(K, 1), state.n_columns(T)))
    tab[:K, state.ID] = t.id
    tab[:K, state.X : state.X + 4] = t.x
    tab[:K, state.P0 : state.P0 + 16] = t.P.reshape(K, 16)
    tab[:K, state.BORN] = t.born_ns - t0
    tab[:K, state.LAST_HIT] = t.last_hit_ns - t0
    for col, name in (
        (state.AGE, "age"),
        (state.HITS, "hits"),
        (state.MISSES, "misses"),
        (state.HISTORY, "history"),
        (state.LEAD_LEFT, "lead_left"),
        (state.LEAD_RIGHT, "lead_right"),
        (state.MOVING_TIME, "moving_time"),
        (state.SIZE, "size"),
        (state.CONFIRMED, "confirmed"),
        (state.OCCLUDED, "occluded"),
        (state.HIT, "hit"),
        (state.CLS, "cls"),
        (state.MOBILITY, "mobility"),
        (state.TAIL_COUNT, "tail_count"),
        (state.LEG_SCORE, "leg_score"),
        (state.LEG_HITS, "leg_hits"),
        (state.IS_PERSON, "person"),
        (state.STILL_TIME, "still_time"),
        (state.FREE, "free"),
    ):
        tab[:K, col] = getattr(t, name)
    tab[:K, state.VOTES : state.VOTES + 5] = t.votes
    tab[:K, state.FIRST_X : state.FIRST_X + 2] = t.first
    tab[:K, state.LAST_X : state.LAST_X + 2] = t.last
    on_bg = ref._on_bg
    tab[: min(K, len(on_bg)), state.ON_BG] = on_bg[:K]
    tab[:K, state.TAIL :] = t.tail.reshape(K, 2 * T)
    return tab


def same_tracks(ref: ReferenceTracker, t0: int, tab: np.ndarray, n: int, what: str, on_bg: bool = False) -> None:
    want = to_table(ref, t0)
    assert n == len(ref.tracks), what
    cols = np.ones(want.shape[1], bool)
    cols[state.ON_BG] = on_bg  # the reference keeps it apart, for this scan only
    np.testing.assert_allclose(tab[:n][:, cols], want[:n][:, cols], rtol=0, atol=1e-9, err_msg=what)


def meas_arrays(m: Measurements) -> ScanMeasurements:
    """The measurements as the compiled step takes them (leg candidates (L, 5), see with_candidates)."""
    raw = with_candidates(m)[0].raw_legs
    return ScanMeasurements(
        np.ascontiguousarray(m.x, np.float64),
        np.ascontiguousarray(m.y, np.float64),
        np.ascontiguousarray(m.size, np.float64),
        np.ascontiguousarray(m.kind, np.int64),
        np.ascontiguousarray(m.legs, np.float64),
        raw,
        np.ascontiguousarray(m.prob, np.float64),
    )


def same_meas(got: tuple, m: Measurements, what: str) -> None:
    x, y, size, kind, legs = got[:5]
    np.testing.assert_array_equal(kind, m.kind, err_msg=what)
    for a, b in ((x, m.x), (y, m.y), (size, m.size), (legs, m.legs)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, err_msg=what)


def same_candidates(raw: np.ndarray, m: Measurements, what: str) -> None:
    """The compiled step's leg candidates (L, 5) are the reference's (padded as with_candidates pads them)."""
    np.testing.assert_array_equal(raw, with_candidates(m)[0].raw_legs, err_msg=what)


def context(ref: ReferenceTracker) -> np.ndarray:
    ctx = state.new_context()
    ctx[state.C_NEXT_ID] = ref.next_id
    if ref._carry_pose is not None:
        ctx[state.C_CARRY_POSED] = 1.0
        ctx[state.C_CARRY_PX], ctx[state.C_CARRY_PY] = ref._carry_pose
    if ref._bg_score is not None:
        ctx[state.C_BG_READY] = 1.0
        ctx[state.C_BG_X0], ctx[state.C_BG_Y0] = ref._bg_origin
        ctx[state.C_BG_LO], ctx[state.C_BG_HI] = ref._bg_lo, ref._bg_hi
        ctx[state.C_BG_COUNT], ctx[state.C_BG_SCAN] = ref._bg_count, ref._bg_scan
    ctx[state.C_KEPT_N], ctx[state.C_KEPT_NEXT] = ref.kept_n, ref.kept_next
    return ctx


# -------------------------------------------------------------------------------------------- lockstep
def lockstep(
    ref: ReferenceTracker,
    t0: int,
    stamp_ns: int,
    meas: Measurements,
    ranges: np.ndarray | None,
    pose: np.ndarray | None,
) -> None:
    """ReferenceTracker.step, phase by phase, each compiled phase run on the reference's state just before
    that phase and compared with the reference's state just after it."""
    p = ref.params
    learned = ref.learned
    stamp = stamp_ns - t0
    has_pose = pose is not None
    pose_arr = np.zeros(3) if pose is None else np.asarray(pose, np.float64)
    bg = ref._bg_score if ref._bg_score is not None else np.zeros(0)
    geo = (
        np.array([0.0, 1.0, np.inf, 0.0, 0.0])
        if ref.geometry is None
        else np.array(
            [ref.geometry.angle_min, ref.geometry.angle_increment, ref.geometry.range_max, 1.0, ref.geometry.range_min]
        )
    )
    rng = np.zeros(0, np.float32) if ranges is None else np.ascontiguousarray(ranges, np.float32)
    dt = 0.0 if ref.stamp_ns is None else max((stamp_ns - ref.stamp_ns) * 1e-9, 0.0)
    ref._dt, ref.stamp_ns, ref.pose = dt, stamp_ns, None if pose is None else pose_arr
    t = ref.tracks
    n = len(t)
    group = kind_groups(t.votes, t.mobility, t.person)
    ref._compat_row = np.where(t.confirmed, group, 4)
    tab = to_table(ref, t0)
    crow = np.array([_association.kind_group(tab, k) if t.confirmed[k] else 4 for k in range(n)], np.int64)
    np.testing.assert_array_equal(crow, ref._compat_row)
    kalman_predict(t.x, t.P, dt, np.where((group == 0) | (group == 5), p.person_process_noise, p.process_noise))
    _association.predict(tab, n, dt, PRM)
    same_tracks(ref, t0, tab, n, "predict")
    px, py, pc, ps = ref._sensor()
    meas, ref._has_prob = with_candidates(meas)
    m = moved(meas, ref.pose)
    if has_pose:
        a = meas_arrays(meas)
        got = _scan_measurements.moved(a[0], a[1], a[4], a[5], px, py, pc, ps)
        same_meas((got[0], got[1], m.size, m.kind, got[2]), m, "moved")
        np.testing.assert_array_equal(got[3], m.raw_legs)
    ctx = context(ref)
    carry = (ref.carry_ref.copy(), ref.carry_seen.copy(), ref.carry_away.copy())
    _background.carried_update(*carry, rng, ranges is not None, has_pose, pose_arr, geo, ctx, PRM)
    ref._carried_update(ranges)
    for got, want in zip(carry, (ref.carry_ref, ref.carry_seen, ref.carry_away), strict=True):
        np.testing.assert_array_equal(got, want)
    assert ctx[state.C_CARRY_POSED] == (ref._carry_pose is not None)
    sensor = (rng, ranges is not None, has_pose, pose_arr, geo)
    frame = (px, py, pc, ps)
    got = _background.off_background(tab, n, meas_arrays(m), bg, ctx, frame, sensor, carry, PRM)
    m = ref._off_background(t, m)
    same_meas(got, m, "off background")
    same_candidates(got[5], m, "off background")
    np.testing.assert_array_equal(got[6], m.prob)
    got, got_rows0 = _people.legs_stage(tab, n, meas_arrays(m), PRM)
    m, rows0 = ref._legs(t, m)
    same_meas(got, m, "legs")
    np.testing.assert_array_equal(got_rows0, rows0)
    np.testing.assert_array_equal(got.prob, m.prob)
    same_candidates(got.raw, m, "legs")
    mx, my, msize, mkind, mlegs, raw, mprob = meas_arrays(m)
    compat = _COMPAT_LEARNED if learned else _COMPAT
    rows_c, cols_c = _association.associate(tab, n, mx, my, mkind, mprob, raw, rows0, compat, crow, PRM)
    rows, cols = ref._associate(t, m, rows0)
    np.testing.assert_array_equal(rows_c, rows)
    np.testing.assert_array_equal(cols_c, cols)
    _background.hit_background(tab, n, rows, cols, meas_arrays(m), bg, ctx, frame, PRM)
    ref._hit_background(t, m, rows, cols)
    np.testing.assert_array_equal(tab[:n, state.ON_BG] != 0, ref._on_bg)
    tab = to_table(ref, t0)
    ref._update(t, m, rows, cols)
    _association.update(tab, n, rows, cols, mx, my, mkind, msize, mlegs, PRM)
    same_tracks(ref, t0, tab, n, "update", on_bg=True)
    rows2, cols2 = ref._reacquire(t, m, rows, cols, stamp_ns)
    got2 = _association.reacquire(
        tab, n, rows, cols, mx, my, mkind, stamp, _REACQUIRE_LEARNED if learned else _REACQUIRE, crow, PRM
    )
    np.testing.assert_array_equal(got2[0], rows2)
    np.testing.assert_array_equal(got2[1], cols2)
    same_tracks(ref, t0, tab, n, "reacquire", on_bg=True)
    merged = _association.merge_reacquired(rows, cols, rows2, cols2)
    if len(rows2):
        keep = ~np.isin(cols, cols2)
        ref._superseded = rows[~keep]
        rows, cols = np.concatenate([rows[keep], rows2]), np.concatenate([cols[keep], cols2])
    np.testing.assert_array_equal(merged[0], rows)
    np.testing.assert_array_equal(merged[1], cols)
    np.testing.assert_array_equal(merged[2], ref._superseded)
    superseded = ref._superseded.copy()
    ref._leg_evidence(t, m, rows, cols)
    _people.leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, mprob, raw, ref._has_prob, PRM)
    same_tracks(ref, t0, tab, n, "leg evidence", on_bg=True)
    ref._free_legs(t, m, rows, cols)
    kept = (ref.kept_ranges.copy(), ref.kept_poses.copy())
    _people.free_legs(tab, rows, cols, mx, my, mkind, mlegs, kept, geo, context(ref), PRM)
    same_tracks(ref, t0, tab, n, "free legs", on_bg=True)
    ref._occlusion(t, ranges)
    _life_cycle.occlusion(tab, n, rng, ranges is not None, geo, has_pose, pose_arr, PRM)
    same_tracks(ref, t0, tab, n, "occlusion", on_bg=True)
    ref._life_cycle(t, stamp_ns)
    n = _life_cycle.life_cycle(tab, n, stamp, superseded, learned, PRM)
    same_tracks(ref, t0, tab, n, "life cycle", on_bg=True)
    ctx = context(ref)
    ref._spawn(m, rows, cols, stamp_ns)
    tab, n = _life_cycle.spawn(tab, n, cols, meas_arrays(m), ref._has_prob, stamp, ctx, PRM)
    same_tracks(ref, t0, tab, n, "spawn")
    assert ctx[state.C_NEXT_ID] == ref.next_id
    tab = to_table(ref, t0)
    ref._classify()
    _classify.classify(tab, len(ref.tracks), dt, stamp, learned, PRM)
    same_tracks(ref, t0, tab, n, "classify")
    ref._push_tail()
    _life_cycle.push_tail(tab, n, PRM)
    same_tracks(ref, t0, tab, n, "tail")
    if ref._bg_score is not None:
        before = (ref._bg_score.copy(), np.maximum(ref._bg_mark, 0), ref._bg_active.copy(), np.zeros((65536, 2)))
        ctx = context(ref)
    ref._background(ranges)
    if ref._bg_score is not None:
        if ctx[state.C_BG_READY] == 0:  # the grid was made this scan
            before = (
                np.zeros_like(ref._bg_score),
                np.zeros_like(ref._bg_mark),
                np.zeros_like(ref._bg_active),
                np.zeros((65536, 2)),
            )
        cos_a, sin_a = ref._cos, ref._sin
        _background.background(before, ctx, sensor, (cos_a, sin_a), frame, dt, tab, n, PRM)
        # inactive cells: mark -1 in the reference, 0 in the compiled grid
        for got, want in zip(before[:3], (ref._bg_score, np.maximum(ref._bg_mark, 0), ref._bg_active), strict=True):
            np.testing.assert_array_equal(got, want)
        assert ctx[state.C_BG_COUNT] == ref._bg_count and ctx[state.C_BG_SCAN] == ref._bg_scan
        assert (ctx[state.C_BG_X0], ctx[state.C_BG_Y0]) == ref._bg_origin
    ctx = context(ref)
    ctx[state.C_KEPT_STAMP] = -1.0 if ref.kept_stamp is None else ref.kept_stamp - t0
    kept = (ref.kept_ranges.copy(), ref.kept_poses.copy())
    ref._keep_scan(ranges, stamp_ns)
    _people.keep_scan(*kept, rng, ranges is not None and geo[3] != 0, pose_arr, stamp, ctx, PRM)
    np.testing.assert_array_equal(kept[0], ref.kept_ranges)
    np.testing.assert_array_equal(kept[1], ref.kept_poses)
    assert (ctx[state.C_KEPT_N], ctx[state.C_KEPT_NEXT]) == (ref.kept_n, ref.kept_next)
    out = np.zeros(n, TRACK_DTYPE)
    _step.write_tracks(out, 0, tab, n, has_pose, pose_arr)
    want = ref.output()
    for name in EXACT:
        np.testing.assert_array_equal(out[name], want[name])
    for name in ("x", "y", "vx", "vy", "world_x", "world_y", "size", "covariance"):
        np.testing.assert_allclose(out[name], want[name], rtol=1e-6, atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "leg_model"), [("hall.mcap", "default"), ("patrol.mcap", "default"), ("crowd6.mcap", "paper")]
)
def test_every_phase_equals_the_reference_scan_by_scan(name: str, leg_model: str):
    run, feats, _, poses = sample(name, leg_model)
    learned = leg_model != "paper"
    ref = ReferenceTracker(P, run.geometry, learned=learned, leg_threshold=THR)
    t0 = int(run.stamps[0])
    for i, f in enumerate(feats):
        m = reference_measurements(f, P, learned, THR)
        got = _flat_measurements(f, learned)
        same_meas(got, m, f"measurements of scan {i}")
        same_candidates(got[5], m, f"leg candidates of scan {i}")
        np.testing.assert_array_equal(got[6], m.prob)
        lockstep(ref, t0, int(run.stamps[i]), m, run.ranges[i], None if poses is None else poses[i])


def _flat_measurements(f, learned: bool) -> tuple:
    """The compiled features-to-measurements of one scan."""
    from datmo_cli.tracking.tracker import _flat

    block = _flat([f])  # one scan: its offsets are (0, count) and the arrays its own
    if learned:
        return _scan_measurements.learned_measurements(block.circles, block.blobs, block.lines, block.legs, PRM)
    return _scan_measurements.paper_measurements(block.circles, block.blobs, block.lines, PRM)


# ------------------------------------------------------------------------------------------- whole runs
def reference_run(run, feats, poses, learned: bool, frame: str) -> tuple[list, list, ReferenceTracker]:
    ref = ReferenceTracker(P, run.geometry, learned=learned, leg_threshold=THR)
    tracks, markers = [], []
    for i, f in enumerate(feats):
        out = ref.step(
            int(run.stamps[i]),
            reference_measurements(f, P, learned, THR),
            run.ranges[i],
            None if poses is None else poses[i],
        )
        tracks.append(out)
        markers.append(
            track_markers(
                int(run.stamps[i]), frame, out, ref.tracks.tail, ref.tracks.tail_count, world=poses is not None
            )
        )
    return tracks, markers, ref


@pytest.mark.parametrize("name", LOGS)
def test_whole_runs_equal_the_reference(name: str):
    """track_run (compiled blocks, as datmo track runs) gives the reference's Tracks and markers byte for byte,
    with the leg detector and with the paper's rule; one block for the whole run ends in the same state."""
    for leg_model in ("default", "paper"):
        learned = leg_model != "paper"
        run, feats, odometry, poses = sample(name, leg_model)
        frame = odometry.frame_id if poses is not None else run.geometry.frame_id
        want_tracks, want_markers, ref = reference_run(run, feats, poses, learned, frame)
        got = track_run(run, feats, odometry=odometry, params=P, learned=learned)
        assert sum(len(t) for t in want_tracks) > 0
        for i in range(len(run)):
            assert got.tracks[i].tobytes() == want_tracks[i].tobytes(), f"{leg_model}: tracks of scan {i}"
            assert got.markers[i] == want_markers[i], f"{leg_model}: markers of scan {i}"
        tracker = Tracker(P, run.geometry, learned=learned, leg_threshold=THR)
        block = tracker.track_block(run.stamps, feats, run.ranges, poses)
        assert block.items.tobytes() == np.concatenate(want_tracks).tobytes()
        same_tracks(ref, int(run.stamps[0]), tracker.tracks.table, len(tracker.tracks), f"{leg_model}: final state")


def test_ideal_features_on_the_hall_equal_the_reference():
    """The benchmark's ideal features (ground truth's objects), the paper's rule, no ranges given."""
    from benchmarks import tracking_scoring as acc
    from datmo_cli.report import decode_channel

    log = mcapio.read_log(SAMPLE_LOGS / "hall.mcap", topics=None)
    run = mcapio.run_from_log(log)
    truth = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    feats = acc.ideal_features(truth.offsets["objects"], truth.items["objects"], np.random.default_rng(0))
    ref = ReferenceTracker(P, run.geometry)
    tracker = Tracker(P, run.geometry)
    want = [
        ref.step(int(s), reference_measurements(f, P), run.ranges[i])
        for i, (s, f) in enumerate(zip(run.stamps, feats, strict=True))
    ]
    block = tracker.track_block(run.stamps, feats, run.ranges)
    assert block.items.tobytes() == np.concatenate(want).tobytes()
    assert (np.diff(block.offsets) == [len(w) for w in want]).all()
    ref2, tracker2 = ReferenceTracker(P), Tracker(P)  # no geometry: no occlusion, no background
    for s, f in zip(run.stamps[:100], feats[:100], strict=True):
        a, b = ref2.step(int(s), reference_measurements(f, P)), tracker2.step(int(s), f)
        assert a.tobytes() == b.tobytes()


# -------------------------------------------------------------------------------------------- random scenes
GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0)


def weak_legs(feats: list, rng: np.random.Generator) -> None:
    """Give the legs of `feats` leg probabilities from the whole range, in place: about half strong (at least
    THR), a quarter weak but at least person_maintain, a quarter below it; and each leg the blob of its own beams
    (as a real leg's cluster is also a segment), which is what a weak candidate is measured as."""
    from benchmarks.synthetic_features import BLOB_DTYPE

    for f in feats:
        g = f.legs
        u = rng.uniform(size=len(g))
        g["probability"] = np.where(
            u < 0.5,
            rng.uniform(THR, 1.0, len(g)),
            np.where(
                u < 0.75, rng.uniform(P.person_maintain, THR, len(g)), rng.uniform(0.01, P.person_maintain, len(g))
            ),
        )
        b = np.zeros(len(g), BLOB_DTYPE)
        for name in ("x", "y", "first", "last", "segment"):
            b[name] = g[name]
        b["size"] = g["width"]
        f.blobs = np.concatenate([f.blobs, b])


@st.composite
def scenes(draw) -> tuple:
    """A few objects (circles, legs of people with leg probabilities from the whole range, blobs, short lines)
    moving straight, seen with dropouts, over up to 25 scans at uneven stamps; sometimes a moving sensor's poses;
    sometimes ranges: a near wall, or returns on the objects with a wall the sensor nears and a pair of legs fixed
    in the sensor frame on beams whose returns stay put (a part of the robot)."""
    seed = draw(st.integers(0, 2**32 - 1))
    n_scans = draw(st.integers(1, 25))
    rng = np.random.default_rng(seed)
    n_obj = draw(st.integers(0, 8))
    start = rng.uniform([-1, -3], [6, 3], (n_obj, 2))
    vel = rng.uniform(-1.2, 1.2, (n_obj, 2))
    kind = rng.integers(0, 4, n_obj)
    stamps = np.cumsum(rng.integers(50_000_000, 400_000_000, n_scans)) + 10**18
    ranges_kind = draw(st.integers(0, 2))
    part = 0.6 * np.array([np.cos(-1.13), np.sin(-1.13)])  # about beam 50: something the robot carries
    scans = []
    for i in range(n_scans):
        s: dict = {"circles": [], "legs": [], "blobs": [], "lines": []}
        tt = (stamps[i] - stamps[0]) * 1e-9
        for o in range(n_obj):
            if rng.uniform() < 0.15:
                continue
            x, y = start[o] + vel[o] * tt + rng.normal(0, 0.02, 2)
            if kind[o] == 0:
                s["circles"].append((x, y, rng.uniform(0.05, 0.4)))
            elif kind[o] == 1:  # a person's legs, sometimes one hidden
                s["legs"].append((x, y + 0.15, 0.12))
                if rng.uniform() < 0.8:
                    s["legs"].append((x + 0.1 * np.sin(3 * tt), y - 0.15, 0.12))
            elif kind[o] == 2:
                s["blobs"].append((x, y, rng.uniform(0.1, 0.5)))
            else:
                s["lines"].append((x - 0.3, y, x + 0.3, y + 0.1))
        if ranges_kind == 2:
            s["legs"] += [(part[0], part[1] + 0.1, 0.1), (part[0], part[1] - 0.1, 0.1)]
        scans.append(s)
    feats = features_from_lists(scans)
    weak_legs(feats, rng)
    poses = None
    if draw(st.booleans()):
        poses = np.stack([0.3 * np.arange(n_scans), 0.1 * np.arange(n_scans), 0.05 * np.arange(n_scans)], axis=1)
    ranges = None
    if ranges_kind == 1:
        ranges = np.full((n_scans, GEOM.n_beams), 7.5, np.float32)
        ranges[:, 150:200] = rng.uniform(0.5, 7.5, (n_scans, 1))
    elif ranges_kind == 2:
        ranges = (7.5 - 0.2 * np.arange(n_scans)[:, None] + np.zeros(GEOM.n_beams)).astype(np.float32)
        for i, s in enumerate(scans):
            for x, y, *_ in s["circles"] + s["legs"] + s["blobs"] + s["lines"]:
                b = int(np.rint((np.arctan2(y, x) - GEOM.angle_min) / GEOM.angle_increment))
                r = ranges[i, max(b - 3, 0) : max(b + 4, 0)]
                r[:] = np.minimum(r, np.hypot(x, y))
    return stamps, feats, poses, ranges, draw(st.booleans())


@settings(max_examples=25, deadline=None)
@given(scene=scenes())
def test_random_scenes_equal_the_reference(scene: tuple):
    stamps, feats, poses, ranges, learned = scene
    ref = ReferenceTracker(P, GEOM, learned=learned, leg_threshold=THR)
    step = Tracker(P, GEOM, learned=learned, leg_threshold=THR)
    want = []
    for i, f in enumerate(feats):
        pose = None if poses is None else poses[i]
        rng = None if ranges is None else ranges[i]
        m = reference_measurements(f, P, learned, THR)
        a = ref.step(int(stamps[i]), m, rng, pose)
        b = step.step(int(stamps[i]), m, rng, pose)  # the Measurements form of step
        assert a.tobytes() == b.tobytes(), f"scan {i}"
        np.testing.assert_allclose(step.tracks.x, ref.tracks.x, rtol=0, atol=1e-9)
        want.append(a)
    block = Tracker(P, GEOM, learned=learned, leg_threshold=THR).track_block(stamps, feats, ranges, poses)
    assert block.items.tobytes() == np.concatenate(want).tobytes()


@settings(max_examples=6, deadline=None)
@given(scene=scenes())
def test_every_phase_equals_the_reference_on_small_scenes(scene: tuple):
    """The lockstep of the sample logs on small random scenes (a few objects, a few scans): every compiled
    phase called directly on the reference's state, and the compiled features-to-measurements."""
    stamps, feats, poses, ranges, learned = scene
    ref = ReferenceTracker(P, GEOM, learned=learned, leg_threshold=THR)
    for i, f in enumerate(feats):
        m = reference_measurements(f, P, learned, THR)
        got = _flat_measurements(f, learned)
        same_meas(got, m, f"measurements of scan {i}")
        same_candidates(got[5], m, f"leg candidates of scan {i}")
        np.testing.assert_array_equal(got[6], m.prob)
        lockstep(
            ref,
            int(stamps[0]),
            int(stamps[i]),
            m,
            None if ranges is None else ranges[i],
            None if poses is None else poses[i],
        )


def test_the_table_grows_past_its_capacity():
    """A scan with more new objects than the table holds: the table doubles, nothing is lost."""
    n = 150
    xy = [(0.5 * (k % 15), 0.5 * (k // 15) - 2.5, 0.3) for k in range(n)]
    feats = features_from_lists([{"circles": xy}] * 4)
    tracker, ref = Tracker(P, GEOM), ReferenceTracker(P, GEOM)
    assert len(tracker.tracks.table) < n
    for k, f in enumerate(feats):
        a = ref.step(k * 100_000_000, reference_measurements(f, P))
        b = tracker.step(k * 100_000_000, f)
        assert a.tobytes() == b.tobytes()
    assert len(tracker.tracks) == n and len(tracker.tracks.table) >= n
    assert tracker.tracks.tail.shape == (n, P.tail_length, 2)
    np.testing.assert_array_equal(tracker.tracks.tail_count, ref.tracks.tail_count)
