"""The kernels that run whole stages (a block of scans through tracking, feature extraction or ego-motion, a
block of detections into the landmark database) and their helpers, called directly on small scenes and
compared with the plain references of tests/reference_*.py; tests/test_kernels_reference.py checks the
kernels they call one by one."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

from datmo_cli.perception import feature_layout as FL
from datmo_cli.perception import hough_circles as HC
from datmo_cli.perception import hough_lines as HL
from datmo_cli.perception import icp as KI
from datmo_cli.perception import landmark_database as LDB
from datmo_cli.perception import leg_features as LF
from datmo_cli.perception import scan_extractor as SX
from datmo_cli.perception import scan_odometry as KO
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking import _step, state
from datmo_cli.tracking.tracker import TRACK_DTYPE, Tracker, _flat
from tests import reference_perception as rp
from tests.reference_tracking import ReferenceTracker, reference_measurements
from tests.test_tracking_step import GEOM, THR, P, meas_arrays, scenes

pytestmark = pytest.mark.unit


# ------------------------------------------------------------------------------------------------ tracking
def _state(learned: bool) -> tuple:
    """A new tracker's state as the compiled step takes it: (table, context, prm, geometry, beam directions
    (cos, sin), background grid, carried beams, rules)."""
    t = Tracker(P, GEOM, learned=learned, leg_threshold=THR)
    return t.tracks.table, t._ctx, t._prm, t._geo, (t._cos, t._sin), t._bg, t._carry, t._rules


@settings(max_examples=6, deadline=None)
@given(scene=scenes())
def test_track_block_step_measurements_and_track_scan(scene: tuple):
    """A small scene through _step.track_block (one call), _step.step_measurements and _step.track_scan (scan by
    scan, each on its own state): every scan's Track elements are the reference tracker's byte for byte."""
    stamps, feats, poses, ranges, learned = scene
    N = len(stamps)
    ref = ReferenceTracker(P, GEOM, learned=learned, leg_threshold=THR)
    want = []
    for i, f in enumerate(feats):
        want.append(
            ref.step(
                int(stamps[i]),
                reference_measurements(f, P, learned, THR),
                None if ranges is None else ranges[i],
                None if poses is None else poses[i],
            )
        )
    rel = stamps - stamps[0]
    ranges_arg = np.zeros((N, 0), np.float32) if ranges is None else ranges
    poses_arg = np.zeros((N, 3)) if poses is None else poses

    tab, ctx, prm, geo, beam_dirs, bg, carry, rules = _state(learned)
    cap, T = 4, P.tail_length
    offsets = np.zeros(N + 1, np.int64)
    _, out, _, count = _step.track_block(
        tab,
        ctx,
        prm,
        (rel, ranges_arg, ranges is not None, poses_arg, poses is not None),
        _flat(feats),
        geo,
        beam_dirs,
        bg,
        carry,
        rules,
        (np.zeros(cap, TRACK_DTYPE), True, np.zeros((cap, T, 2)), np.zeros(cap, np.int64), offsets),
    )
    np.testing.assert_array_equal(np.diff(offsets), [len(w) for w in want])
    assert out[: offsets[-1]].tobytes() == np.concatenate(want).tobytes()
    assert (count[: offsets[-1]] >= 1).all()

    tab1, ctx1, prm1, geo1, dirs1, bg1, carry1, rules1 = _state(learned)
    tab2, ctx2, prm2, geo2, dirs2, bg2, carry2, rules2 = _state(learned)
    out1 = np.zeros(1, TRACK_DTYPE)
    for i, f in enumerate(feats):
        m = reference_measurements(f, P, learned, THR)
        meas = meas_arrays(m)
        has_prob = m.raw_legs.shape[1] >= 4
        sensor = (ranges_arg[i], ranges is not None, poses is not None, poses_arg[i], geo1)
        tab1, out1 = _step.step_measurements(
            tab1, ctx1, prm1, rel[i], meas, has_prob, sensor, dirs1, bg1, carry1, rules1, out1
        )
        n = int(ctx1[state.C_N_TRACKS])
        assert out1[:n].tobytes() == want[i].tobytes(), f"step_measurements, scan {i}"
        sensor = (ranges_arg[i], ranges is not None, poses is not None, poses_arg[i], geo2)
        tab2 = _step.track_scan(tab2, ctx2, prm2, rel[i], meas, has_prob, sensor, dirs2, bg2, carry2, rules2)
        n2 = int(ctx2[state.C_N_TRACKS])
        got = np.zeros(n2, TRACK_DTYPE)
        _step.write_tracks(got, 0, tab2, n2, poses is not None, poses_arg[i])
        assert got.tobytes() == want[i].tobytes(), f"track_scan, scan {i}"


# --------------------------------------------------------------------------------------------- ego-motion
def test_gather():
    """Each side of a beam's neighbourhood: the count and sums of u, v, uu, uv, vv of the points the reference
    walk takes, and its farthest distance."""
    rng = np.random.default_rng(31)
    angles = np.radians(np.linspace(-60.0, 60.0, 121))
    r = (2.0 + 0.3 * np.sin(angles * 5) + rng.normal(0, 0.01, 121)).astype(np.float32)
    r[rng.random(121) < 0.1] = np.nan
    r[40:44] = 1.2  # a near object: the walk stops at its edge
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    for b in np.flatnonzero(np.isfinite(r)).tolist():
        for direction in (-1, 1):
            for radius, gap, window in ((0.1, 0.5, 20), (0.3, 0.08, 6)):
                acc = np.zeros(6)
                far = KO._gather(r, cos_a, sin_a, 0.05, 30.0, b, direction, radius, gap, window, acc)
                uv, want_far = rp.gather(r, angles, 0.05, 30.0, b, direction, radius, gap, window)
                u, v = uv[:, 0], uv[:, 1]
                want = [len(uv), u.sum(), v.sum(), (u * u).sum(), (u * v).sum(), (v * v).sum()]
                np.testing.assert_allclose(acc, want, rtol=1e-9, atol=1e-12)
                assert far == pytest.approx(want_far, rel=1e-9, abs=1e-12)


def test_rebuild_map():
    """The map of a ring of keyframes, newest first, after a few keyframes and after the ring wrapped."""
    rng = np.random.default_rng(32)
    slots, beams, cell = 3, 40, 0.25
    kf_x, kf_y, kf_nx, kf_ny = (np.zeros((slots, beams)) for _ in range(4))
    kf_n, kf_pose = np.zeros(slots, np.int64), np.zeros((slots, 3))
    cap = slots * beams
    mx, my, mnx, mny = np.zeros(cap), np.zeros(cap), np.zeros(cap), np.zeros(cap)
    head, nxt = np.full(512, KI.EMPTY, np.int64), np.full(cap, KI.EMPTY, np.int64)
    ring: list = [(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(3))] * slots
    for newest_count in range(1, 6):
        newest, n_kf = (newest_count - 1) % slots, min(newest_count, slots)
        m = int(rng.integers(20, beams))
        pts = rng.uniform(-2, 2, (m, 2))
        ang = rng.uniform(-np.pi, np.pi, m)
        nrm = np.column_stack([np.cos(ang), np.sin(ang)])
        nrm[rng.random(m) < 0.2] = np.nan
        pose = rng.uniform(-0.3, 0.3, 3)
        kf_x[newest, :m], kf_y[newest, :m], kf_nx[newest, :m], kf_ny[newest, :m] = (
            pts[:, 0],
            pts[:, 1],
            nrm[:, 0],
            nrm[:, 1],
        )
        kf_n[newest], kf_pose[newest] = m, pose
        ring[newest] = (pts, nrm, pose)
        keyframes = (kf_x, kf_y, kf_nx, kf_ny, kf_n, kf_pose)
        local_map = KI.LocalMap(mx=mx, my=my, mnx=mnx, mny=mny, cell=cell, head=head, nxt=nxt)
        count = KO.rebuild_map(keyframes, newest, n_kf, 0.2, local_map)
        want_xy, want_n = rp.rebuild_map(ring, newest, n_kf, 0.2, cap)
        assert count == len(want_xy)
        np.testing.assert_allclose(np.column_stack([mx, my])[:count], want_xy, atol=1e-12)
        np.testing.assert_allclose(np.column_stack([mnx, mny])[:count], want_n, atol=1e-12)


def test_predict_and_match():
    """_predict is the reference's constant-velocity guess (the previous pose moved on by the previous motion
    times the ratio of the time steps, at most 3); _match aligns a scan from it, and from each recovery move when
    the inlier share is low or ICP did not converge, as the reference's odometry does: the same pose and figures."""
    from datmo_cli.perception.egomotion import IcpParams
    from tests.test_egomotion import G361, START, cast, room_map, source_points

    rng = np.random.default_rng(41)
    for trial in range(20):
        poses, dt = rng.uniform(-1, 1, (3, 3)), rng.uniform(0.0, 0.3, 3)
        dt[1] = 0.0 if trial % 5 == 0 else dt[1]
        want = poses[1]
        if dt[1] > 0:
            motion = rp.pose_of(np.linalg.inv(rp.se2(*poses[0])) @ rp.se2(*poses[1]))
            want = rp.compose(poses[1], min(max(dt[2] / dt[1], 0.0), 3.0) * motion)
        np.testing.assert_allclose(KO._predict(poses, dt, 2), want, atol=1e-12)
        np.testing.assert_allclose(KO._predict(poses, dt, 1), poses[0], atol=0)
    p = IcpParams()
    (mx, my, mnx, mny), head, nxt = room_map(G361, cast(START, G361.angles(), noise=0.005, rng=rng))
    local_map = KI.LocalMap(mx=mx, my=my, mnx=mnx, mny=mny, cell=p.max_dist, head=head, nxt=nxt)
    map_xy, map_n = np.stack([mx, my], 1), np.stack([mnx, mny], 1)
    icp = (p.max_dist0, p.max_dist, p.robust_scale, p.inlier_tol, p.max_iter, p.prior_weight)
    moves = np.asarray(p.recovery_moves, np.float64).reshape(-1, 3)
    poses, dt = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.0, 0.0]]), np.array([0.0, 0.1, 0.1])
    flags_seen = 0
    for turn in (0.02, 0.5):  # a small move, and a sudden turn the recovery moves find
        cur = cast((START[0] + 0.05, START[1], START[2] + turn), G361.angles(), noise=0.005, rng=rng)
        sx, sy = source_points(G361, cur)
        n, src = len(sx), np.stack([sx, sy], 1)
        pose, scratch = np.zeros(3), np.zeros(3)
        got = KO._match((sx, sy), n, poses, dt, 2, local_map, icp, (p.min_inlier_share, moves), pose, scratch)
        want_pose, (matched, mean_res, inliers, iters) = rp.icp_align(
            src, KO._predict(poses, dt, 2), map_xy, map_n, *icp
        )
        share, flags = inliers / max(n, 1), 0
        if share < p.min_inlier_share or iters >= p.max_iter:
            for move in moves:
                moved, (m2, r2, i2, it2) = rp.icp_align(src, rp.compose(poses[1], move), map_xy, map_n, *icp)
                iters += it2
                if m2 >= KI.MIN_MATCHES and i2 / max(n, 1) > share:
                    share, matched, mean_res, inliers, want_pose = i2 / max(n, 1), m2, r2, i2, moved
                    flags |= KO.FLAG_RECOVERED
        if matched < KI.MIN_MATCHES:
            flags |= KO.FLAG_FAILED
        assert (got[0], got[2], got[3], got[5]) == (matched, inliers, iters, flags)
        assert got[1] == pytest.approx(mean_res, rel=1e-9) and got[4] == pytest.approx(share, rel=1e-12)
        np.testing.assert_allclose(pose, want_pose, atol=1e-9)
        flags_seen |= flags
    assert flags_seen & KO.FLAG_RECOVERED


# ------------------------------------------------------------------------------------------------- legs
def test_segment_features():
    """The shape features of a segment's points; the scan-context columns (angle, occlusion, jumps, density)
    are block_features' and are left zero."""
    from datmo_cli.perception import legs

    rng = np.random.default_rng(33)
    angles = np.radians(np.linspace(-40.0, 40.0, 60))
    context = [
        legs.FEATURE_NAMES.index(n)
        for n in (
            "subtended_angle",
            "occluded_start",
            "occluded_end",
            "jump_start",
            "jump_end",
            "density",
            "relative_curvature",
        )
    ]
    shape = np.setdiff1d(np.arange(LF.N_FEATURES), context)
    for _ in range(20):
        r = (
            rng.uniform(1.0, 3.0) + 0.05 * np.cos(np.linspace(-1, 1, 60)) * rng.uniform(0, 1) + rng.normal(0, 0.01, 60)
        ).astype(np.float32)
        s = int(rng.integers(0, 50))
        e = s + int(rng.integers(1, 60 - s + 1))
        x = r[s:e].astype(np.float64) * np.cos(angles[s:e])
        y = r[s:e].astype(np.float64) * np.sin(angles[s:e])
        out, work, step = np.zeros(LF.N_FEATURES), np.empty(e - s), np.empty(e - s)
        LF.segment_features(x, y, e - s, legs.RADIUS_CLIP, work, step, out)
        want = rp.segment_features(r, angles, s, e, 0.05, 30.0)
        np.testing.assert_allclose(out[shape], want[shape], rtol=1e-6, atol=1e-7)
        assert (out[context] == 0).all()


# -------------------------------------------------------------------------------------------- landmarks
def test_beyond():
    from datmo_cli.perception import landmarks

    rng = np.random.default_rng(34)
    ranges = rng.uniform(0.0, 9.0, (3, 30)).astype(np.float32)
    ranges[rng.random((3, 30)) < 0.3] = np.nan
    scan, beam = rng.integers(0, 3, 50), rng.integers(0, 30, 50)
    for step in (-1, 1):
        out, where = np.full(50, np.inf), np.full(50, -1, np.int64)
        landmarks._beyond(ranges, scan, beam, step, 0.5, 8.0, 2, out, where)
        want_out, want_where = rp.beyond(ranges, scan, beam, step, 0.5, 8.0, 2)
        np.testing.assert_array_equal(out, want_out)
        np.testing.assert_array_equal(where, want_where)
        assert (where >= 0).any() and (where < 0).any()


def test_benches():
    from datmo_cli.logs.vocabulary import LANDMARK_BENCH
    from datmo_cli.perception import landmarks

    rng = np.random.default_rng(35)
    n_scans = 6
    circles, lines = [], []
    for k in range(n_scans):
        for _ in range(int(rng.integers(0, 5))):
            circles.append((k, *rng.uniform(-2, 2, 2), rng.uniform(0.1, 0.3)))
        for _ in range(int(rng.integers(0, 4))):
            x0, y0 = rng.uniform(-2, 2, 2)
            a, n = rng.uniform(-np.pi, np.pi), rng.uniform(0.2, 2.0)
            lines.append((k, x0, y0, x0 + n * np.cos(a), y0 + n * np.sin(a)))
        if k % 2 == 0:  # a bench: two supports and a seat between them
            cx, cy = rng.uniform(-1, 1, 2)
            circles += [(k, cx - 0.7, cy, 0.15), (k, cx + 0.7, cy, 0.15)]
            lines.append((k, cx - 0.5, cy + 0.05, cx + 0.5, cy + 0.1))
    circles = np.array(sorted(circles, key=lambda c: c[0]))
    lines = np.array(sorted(lines, key=lambda ln: ln[0]))
    line_offsets = np.searchsorted(lines[:, 0], np.arange(n_scans + 1)).astype(np.int64)
    out = np.zeros((len(circles) ** 2, 6))
    n = landmarks._benches(
        circles[:, 0].astype(np.int64),
        circles[:, 1],
        circles[:, 2],
        circles[:, 3],
        lines[:, 1],
        lines[:, 2],
        lines[:, 3],
        lines[:, 4],
        line_offsets,
        FeatureParams(bench_min_length=0.6, bench_max_length=2.5).kernel_vector(),
        out,
    )
    want = rp.benches(circles, lines, 0.6, 2.5, LANDMARK_BENCH)
    assert n == len(want) >= n_scans // 2
    np.testing.assert_allclose(out[:n], want, rtol=1e-12, atol=1e-12)


def _landmark_scene(rng: np.random.Generator, n_scans: int) -> np.ndarray:
    """Detections (scan, type, x, y, orientation, size) of still landmarks of every type seen with noise and
    misses, a drifting column, columns at a bench's supports, and clutter seen once."""
    from datmo_cli.logs.vocabulary import LANDMARK_BENCH, LANDMARK_COLUMN

    still = [(t, *rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi), rng.uniform(0.1, 0.5)) for t in range(6)]
    still += [(LANDMARK_BENCH, 1.0, 2.0, 0.3, 1.6)]
    for sgn in (-1, 1):  # columns where the bench's supports stand (0.13 m in from its ends)
        half = 0.5 * (1.6 - 2 * 0.13)
        still.append((LANDMARK_COLUMN, 1.0 + sgn * half * np.cos(0.3), 2.0 + sgn * half * np.sin(0.3), 0.0, 0.15))
    det = []
    for k in range(n_scans):
        for t, x, y, a, size in still:
            if rng.random() < 0.8:
                det.append((k, t, x + rng.normal(0, 0.02), y + rng.normal(0, 0.02), a, size * rng.uniform(0.9, 1)))
        det.append((k, LANDMARK_COLUMN, -3.0 + 0.02 * k, 1.0, 0.0, 0.2))  # drifts away
        if rng.random() < 0.5:
            det.append((k, rng.integers(0, 6), *rng.uniform(-6, 6, 2), 0.0, 0.3))
    return np.array(det, np.float64)


def test_accumulate_and_hide_bench_supports():
    """The landmark database, folded in two calls (state carried between them), equals the plain statement of
    its rules after every scan: the rows, the stamps first seen, and every scan's snapshot."""

    rng = np.random.default_rng(36)
    n_scans, split = 40, 23
    det = _landmark_scene(rng, n_scans)
    stamps = (np.arange(n_scans) * 100_000_000 + 5 * 10**17).astype(np.int64)
    match, min_count, drift, column_time, forget, support = 0.3, 3, 0.1, 1e9, LDB.FORGET_SCANS, 0.13
    p = FeatureParams(
        landmark_match=match,
        landmark_min_count=min_count,
        column_max_drift=drift,
        column_min_time=column_time / 1e9,
        column_radius_min=support,
    ).kernel_vector()
    cap = len(det) + 1
    db, first_ns, last_ns = np.zeros((cap, LDB.DB_COLUMNS)), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    live, confirmed, counters = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(3, np.int64)
    snaps = []
    for k0, k1 in ((0, split), (split, n_scans)):
        part = np.ascontiguousarray(det[(det[:, 0] >= k0) & (det[:, 0] < k1)])
        size = (k1 - k0) * cap
        snap_idx, snap_vals = np.zeros(size, np.int64), np.zeros((size, 6))
        snap_last, snap_count = np.zeros(size, np.int64), np.zeros(k1 - k0, np.int64)
        state = (db, first_ns, last_ns, live, confirmed, counters)
        ns = LDB.accumulate(part, stamps[k0:k1], k0, p, state, (snap_idx, snap_vals, snap_last, snap_count))
        assert ns == snap_count.sum()
        offsets = np.concatenate([[0], np.cumsum(snap_count)])
        for a, b in zip(offsets[:-1], offsets[1:], strict=True):
            snaps.append([(snap_idx[q], *snap_vals[q], snap_last[q]) for q in range(a, b)])
    rows, want_first, want_snaps = rp.landmark_database(
        det, stamps, match, min_count, drift, column_time, forget, support
    )
    n = counters[LDB.COUNT_ROWS]
    assert n == len(rows)
    np.testing.assert_allclose(db[:n], rows, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(first_ns[:n], want_first)
    for k in range(n_scans):
        assert [s[0] for s in snaps[k]] == [s[0] for s in want_snaps[k]], f"scan {k}"
        np.testing.assert_allclose(
            np.array(snaps[k]).reshape(-1, 8), np.array(want_snaps[k]).reshape(-1, 8), rtol=1e-12, atol=1e-12
        )
    assert rows[:, LDB.DB_MOVED].any() and rows[:, LDB.DB_HIDDEN].sum() == 2 and len(want_snaps[-1]) >= 6
    # accumulate's steps called one by one: _fold each detection, then forget stale candidates and moved
    # columns and hide benches' supports after each scan: the same database
    db1, first1, last1 = np.zeros((cap, LDB.DB_COLUMNS)), np.zeros(cap, np.int64), np.zeros(cap, np.int64)
    live1, confirmed1, counters1 = np.zeros(cap, np.int64), np.zeros(cap, np.int64), np.zeros(3, np.int64)
    state1 = (db1, first1, last1, live1, confirmed1, counters1)
    used = (0, 0, 0)
    for k in range(n_scans):
        for d in det[det[:, 0] == k]:
            used = LDB._fold(d, k, stamps[k], p, state1, used)
        m, nlive, nconf = used
        u = 0
        while u < nlive:  # as accumulate drops them: the last live row takes the dropped one's place
            q = live1[u]
            if (db1[q, LDB.DB_CONFIRMED] == 0 and k - db1[q, 7] > forget) or db1[q, LDB.DB_MOVED] != 0:
                nlive -= 1
                live1[u] = live1[nlive]
            else:
                u += 1
        used = (m, nlive, nconf)
        LDB._hide_bench_supports(db1, confirmed1, nconf, min_count, support)
    assert used[0] == n
    np.testing.assert_allclose(db1[:n], rows, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(first1[:n], want_first)
    # the hiding rule on its own: a confirmed column by a confirmed bench's support end, and one farther off
    db2 = np.zeros((3, LDB.DB_COLUMNS))
    db2[0, :6] = [5, 0.0, 0.0, 0.0, 2.0, 3]
    db2[1, :6] = [4, 0.85 + 0.3, 0.2, 0.0, 0.15, 3]
    db2[2, :6] = [4, -0.87, 0.6, 0.0, 0.15, 3]
    LDB._hide_bench_supports(db2, np.array([0, 1, 2]), 3, 3, 0.15)
    want = [rp.bench_support_hides(db2[q, 1:3], db2[0, 1:5], 0.15) for q in (1, 2)]
    assert db2[1:, LDB.DB_HIDDEN].tolist() == [float(w) for w in want] == [1.0, 0.0]


# ------------------------------------------------------------------------------------------- perception
def _room_scans(n: int, angles: np.ndarray) -> np.ndarray:
    """n scans (ranges, m) of two walls, a column, two legs and clutter, with noise and dropouts."""
    rng = np.random.default_rng(38)
    out = np.empty((n, len(angles)), np.float32)
    for k in range(n):
        r = np.minimum(rp.ray_wall(angles, 4.0, 0.0), rp.ray_wall(angles, 3.0, np.pi / 2))
        for cx, cy, rad in ((2.0, -1.0 + 0.05 * k, 0.2), (1.5, 1.0, 0.06), (1.5, 1.2, 0.06)):
            r = np.minimum(r, rp.ray_circle(angles, cx, cy, rad))
        r = r + rng.normal(0, 0.005, len(r))
        clutter = rng.random(len(r)) < 0.05
        r[clutter] = rng.uniform(0.5, 3.0, clutter.sum())
        r[rng.random(len(r)) < 0.03] = np.nan
        out[k] = r
    return out


def _extract_scan_rows(x, y, segs: list, k: int, vec, cos_t, sin_t, inc: float, acc=None) -> list[np.ndarray]:
    """extract_scan on one scan's points (x, y m, sensor frame) and segments [(start, end)] as scan k, with the
    scratch arrays extract_scans makes (scan_work, for returns up to 8 m), the accumulator `acc` instead of
    its own when given (extract_scan zeroes what it uses): its line, circle and blob rows."""
    B, nt = len(x), len(cos_t)
    starts = np.array([s for s, _ in segs] + [0], np.int64)
    ends = np.array([e for _, e in segs] + [0], np.int64)
    out = [np.zeros((B, c)) for c in (13, 9, 9)]
    work = SX.scan_work(vec, nt, B, 8.0)
    if acc is not None:
        work = work._replace(acc=acc)
    segments = (starts, ends, len(segs))
    nl, nc, nb = SX.extract_scan(x, y, segments, k, vec, (cos_t, sin_t), work, tuple(out), (0, 0, 0), inc)
    return [out[0][:nl], out[1][:nc], out[2][:nb]]


def test_extract_scan_scans_and_parallel():
    """A block of scans through extract_scans (one call) and extract_parallel (split in parts) gives the same
    rows as extract_scan called scan by scan on the reference's segments; each segment is one circle, or its
    lines, or a blob, and blobs are the reference's centroid and extent."""
    from datmo_cli.perception.params import FeatureParams

    p = FeatureParams()
    inc = np.radians(0.5)
    angles = -np.pi / 2 + inc * np.arange(361)
    ranges = _room_scans(3, angles)
    N, B = ranges.shape
    nt = int(round(180.0 / p.theta_resolution))
    theta = np.arange(nt) * (np.pi / nt)
    cos_t, sin_t, vec = np.cos(theta), np.sin(theta), p.kernel_vector()
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    c1 = float(np.sqrt(2.0 * (1.0 - np.cos(inc))))
    args = FL.ExtractSetup(
        cos_a=cos_a,
        sin_a=sin_a,
        cos_inc=float(np.cos(inc)),
        c1=c1,
        range_min=0.05,
        range_max=8.0,
        params=vec,
        cos_t=cos_t,
        sin_t=sin_t,
    )
    none_given, none_off = np.zeros((0, 2), np.int64), np.zeros(0, np.int64)

    def rows() -> list:
        return [np.zeros((N * B, c), np.int64 if c == 2 else np.float64) for c in (2, 13, 9, 9)] + [
            np.zeros((N, 4), np.int64)
        ]

    whole, parallel = rows(), rows()
    SX.extract_scans(ranges, 0, N, args, tuple(whole), (none_given, none_off))
    SX.extract_parallel(ranges, 2, args, tuple(parallel), (none_given, none_off))
    for a, b in zip(whole, parallel, strict=True):
        np.testing.assert_array_equal(a, b)
    seg, lines, circles, blobs, counts = whole
    assert (counts[:, 1:].sum(axis=0) > 0).all()  # lines, circles and blobs

    for k in range(N):
        want_seg = rp.segment(ranges[k], inc, vec[FL.FP_C0], 0.05, 8.0, int(vec[FL.FP_MIN_POINTS]))
        assert [tuple(s) for s in seg[k * B : k * B + counts[k, 0]].tolist()] == want_seg
        r = np.where(np.isfinite(ranges[k]), ranges[k], 0.0).astype(np.float64)
        x, y = r * cos_a, r * sin_a
        got = _extract_scan_rows(x, y, want_seg, k, vec, cos_t, sin_t, inc)
        for j, (g, table) in enumerate(zip(got, (lines, circles, blobs), strict=True)):
            np.testing.assert_array_equal(g, table[k * B : k * B + counts[k, j + 1]])
        kinds = [set() for _ in want_seg]
        for j, g in enumerate(got):
            for row in g:
                s, e = want_seg[int(row[1])]
                assert s <= row[2] <= row[3] < e
                kinds[int(row[1])].add(j)
        assert all(len(kind) == 1 for kind in kinds)
        for row in got[2]:
            s, e = int(row[FL.B_FIRST]), int(row[FL.B_LAST]) + 1
            np.testing.assert_allclose(row[FL.B_X : FL.B_SIZE + 1], rp.blob(x[s:e], y[s:e]), rtol=1e-12, atol=1e-12)


def test_odometry_run():
    """A drive through the test room with a sudden turn (recovered from the recovery moves) and a blank scan:
    every pose and statistic of the compiled run equals the reference's, keyframes included."""
    from datmo_cli.perception.egomotion import IcpParams, _max_window
    from tests.test_egomotion import cast, drive, geometry

    geom, p = geometry(181, 180.0), IcpParams()
    truth = drive(14)
    truth[9:] = [(x, y, t + 0.5) for x, y, t in truth[9:]]  # a sudden turn on the spot
    rng = np.random.default_rng(39)
    ranges = np.stack([cast(pose, geom.angles(), noise=0.005, rng=rng) for pose in truth])
    ranges[5] = np.inf  # nothing seen
    dt = np.full(len(ranges), 0.1)
    dt[0], dt[7] = 0.0, 0.2
    angles = geom.angles().astype(np.float64)
    poses, stats = np.zeros((len(ranges), 3)), np.zeros((len(ranges), KO.N_STATS))
    KO.odometry_run(
        ranges,
        dt,
        (np.cos(angles), np.sin(angles), geom.range_min, geom.range_max),
        (p.max_points, p.source_spacing, p.map_spacing),
        (p.normal_radius, p.max_gap, _max_window(geom), p.planarity),
        (p.max_dist0, p.max_dist, p.robust_scale, p.inlier_tol, p.max_iter, p.prior_weight),
        (p.keyframe_dist, p.keyframe_angle, p.keyframe_share, p.n_keyframes),
        (p.min_inlier_share, np.asarray(p.recovery_moves, np.float64).reshape(-1, 3)),
        poses,
        stats,
    )
    want_poses, want_stats = rp.odometry(ranges, dt, angles, geom.range_min, geom.range_max, p, _max_window(geom))
    np.testing.assert_allclose(poses, want_poses, rtol=0, atol=1e-9)
    exact = [KO.S_MATCHED, KO.S_POINTS, KO.S_FLAGS, KO.S_ITERATIONS]
    np.testing.assert_array_equal(stats[:, exact], want_stats[:, exact])
    np.testing.assert_allclose(stats, want_stats, rtol=1e-9, atol=1e-12)
    flags = stats[:, KO.S_FLAGS].astype(np.int64)
    assert (flags & KO.FLAG_KEYFRAME).sum() >= 2 and (flags & KO.FLAG_RECOVERED).any()


def _feature_scenes(angles: np.ndarray) -> list[np.ndarray]:
    """Scans (ranges, m) for every branch of the decision rule: legs and columns from 0.8 to 7 m, box corners,
    wedges and a zigzag, polygonal pillars, shallow arcs, ellipses, walls with groups of points a few cm proud
    of them (HTL cuts them, the merge rejoins them, or not: bends and steps near its limits); each scene drawn
    twice with a seeded noise (4 mm, or 1 to 2.5 cm where the decision is to be close), each draw also with
    clutter (single points and pairs)."""
    rng = np.random.default_rng(40)

    def polyline(*corners: tuple[float, float]) -> np.ndarray:
        return np.min([rp.ray_segment(angles, a, b) for a, b in zip(corners[:-1], corners[1:], strict=True)], axis=0)

    def polygon(d: float, bearing: float, radius: float, sides: int, turn: float) -> np.ndarray:
        """A regular polygon centred d m away at `bearing`, corners `turn` past the bearing (pi + pi / sides:
        a side faces the scanner)."""
        cx, cy = d * np.cos(bearing), d * np.sin(bearing)
        phi = bearing + turn + 2 * np.pi * np.arange(sides + 1) / sides
        return polyline(*zip(cx + radius * np.cos(phi), cy + radius * np.sin(phi), strict=True))

    def ellipse(d: float, bearing: float, a: float, b: float, turn: float) -> np.ndarray:
        """An ellipse of half axes a and b centred d m away at `bearing`, its a axis `turn` from the x axis."""
        phi = np.linspace(0.0, 2 * np.pi, 49)
        u, v = a * np.cos(phi), b * np.sin(phi)
        return polyline(
            *zip(
                d * np.cos(bearing) + u * np.cos(turn) - v * np.sin(turn),
                d * np.sin(bearing) + u * np.sin(turn) + v * np.cos(turn),
                strict=True,
            )
        )

    def circles(*rings: tuple[float, float, float]) -> np.ndarray:
        return np.min([rp.ray_circle(angles, d * np.cos(b), d * np.sin(b), rad) for d, b, rad in rings], axis=0)

    scenes = [
        # legs (r 6 and 10 cm) and columns (15 to 35 cm) from 0.8 m to 7 m
        circles(
            (0.8, -1.2, 0.06),
            (1.5, -0.8, 0.06),
            (2.5, -0.45, 0.06),
            (3.5, -0.3, 0.06),
            (4.0, -0.2, 0.06),
            (4.5, -0.1, 0.06),
            (5.0, -0.05, 0.06),
            (6.0, 0.0, 0.06),
            (7.0, 0.12, 0.06),
            (1.2, 0.5, 0.15),
            (2.5, 0.85, 0.25),
            (4.0, 1.1, 0.35),
            (1.8, 1.4, 0.35),
            (5.0, 0.25, 0.1),
            (6.0, 0.35, 0.15),
            (7.0, -0.6, 0.2),
            (6.5, 0.7, 0.1),
        ),
        # box corners (small boxes, a large one), triangles (wedges), an octagonal pillar
        np.min(
            [
                polygon(1.2, -1.1, 0.2, 4, 0.0),
                polygon(2.0, -0.6, 0.25, 4, 0.3),
                polygon(3.0, -0.2, 0.7, 4, 0.0),
                polygon(1.5, 0.4, 0.22, 3, 0.0),
                polygon(2.2, 0.9, 0.3, 3, 0.2),
                polygon(1.0, 1.3, 0.35, 8, 0.1),
            ],
            axis=0,
        ),
        # octagonal and hexagonal pillars with a side facing the scanner (three lines, convex); a zigzag
        np.min(
            [
                polygon(1.0, -0.9, 0.33, 8, np.pi + np.pi / 8),
                polygon(1.6, -0.2, 0.36, 8, np.pi + np.pi / 8),
                polygon(1.3, 0.5, 0.3, 6, np.pi + np.pi / 6),
                polyline(
                    *[
                        (
                            1.0 * np.cos(1.1) + off * np.cos(1.1) - v * np.sin(1.1),
                            1.0 * np.sin(1.1) + off * np.sin(1.1) + v * np.cos(1.1),
                        )
                        for v, off in ((-0.33, 0.0), (-0.11, -0.15), (0.11, 0.0), (0.33, -0.15))
                    ]
                ),
            ],
            axis=0,
        ),
        # shallow arcs (large radii, or a column far away) before a far wall
        np.minimum(
            rp.ray_wall(angles, 6.5, 0.0),
            circles((4.4, -0.82, 1.0), (2.0, 0.3, 0.5), (5.5, 0.7, 0.38), (3.5, -0.3, 0.9)),
        ),
        # ellipses (a torso, a bag), and legs and columns, seen with a noise of 1.5 cm: close decisions
        np.min(
            [
                ellipse(1.0, -1.0, 0.2, 0.1, 0.3),
                ellipse(1.5, -0.5, 0.3, 0.18, 1.2),
                ellipse(2.0, 0.0, 0.25, 0.1, 0),
                ellipse(1.2, 0.6, 0.15, 0.1, 0.8),
                ellipse(2.5, 1.0, 0.35, 0.18, 2.0),
                circles((1.3, -1.3, 0.1), (2.0, -0.75, 0.1), (3.0, -0.25, 0.1), (1.8, 0.3, 0.3), (3.0, 1.25, 0.2)),
            ],
            axis=0,
        ),
    ]
    sigma = [0.004] * 4 + [0.015]
    bumps: list[list[tuple[float, int, float, float]]] = [[]] * 5  # (bearing, beams, depth from, to)

    def wall(bearing: float, d: float, bend: float, step: float, half: float = 0.6) -> np.ndarray:
        """A wall facing the scanner d m away, bent by `bend` (degrees) or stepped back `step` (m) where the
        scanner's perpendicular meets it."""
        n, v = np.array([np.cos(bearing), np.sin(bearing)]), np.array([-np.sin(bearing), np.cos(bearing)])
        v2 = np.cos(np.radians(bend)) * v + np.sin(np.radians(bend)) * n
        return np.minimum(
            rp.ray_segment(angles, d * n - half * v, d * n),
            rp.ray_segment(angles, (d + step) * n, (d + step) * n + half * v2),
        )

    # walls cut by HTL at a group of points proud of them, near the merge's limits: bent by 2.5 and 3.5 degrees,
    # stepped back by 3 and 5 cm; then walls seen with 1 cm of noise (a merged line's r_acc is its votes) and a
    # board short enough for a circle (cut and merged, it still counts as two lines: see rp.feature_decision)
    scenes.append(
        np.min(
            [
                wall(-1.1, 2.0, 2.5, 0.0),
                wall(-0.35, 2.2, 3.5, 0.0),
                wall(0.35, 2.0, 0.0, 0.03),
                wall(1.1, 2.2, 0.0, 0.05),
            ],
            axis=0,
        )
    )
    sigma.append(0.004)
    bumps.append([(b, 6, 0.06, 0.08) for b in (-1.1, -0.35, 0.35, 1.1)])
    scenes.append(
        np.min([wall(-0.8, 2.0, 0.0, 0.0), wall(0.6, 2.5, 0.0, 0.0), wall(1.3, 1.5, 0.0, 0.0, 0.375)], axis=0)
    )
    sigma.append(0.01)
    bumps.append([(-0.8, 6, 0.07, 0.07), (0.6, 6, 0.07, 0.07), (1.3, 6, 0.06, 0.08)])
    # a wall with three groups of seven beams 6.5 to 7.5 cm proud of it (HTL often cuts it in three, two merged)
    for _ in range(2):
        scenes.append(rp.ray_wall(angles, 2.0, np.pi / 2 + 0.2))
        sigma.append(0.004)
        bumps.append([(np.radians(a), 7, 0.065, 0.075) for a in (42.5, 57.5, 72.5)])
    # legs and columns seen with a noise of 2 and 2.5 cm: circles near line_min_racc, or under circle_min_points
    for noise in (0.02, 0.025):
        scenes.append(
            circles(
                (1.0, -1.2, 0.1),
                (1.5, -0.8, 0.1),
                (2.0, -0.4, 0.1),
                (3.0, -0.1, 0.1),
                (1.5, 0.3, 0.2),
                (2.0, 0.8, 0.3),
                (1.2, 1.3, 0.15),
                (4.0, 0.5, 0.1),
                (5.0, 0.1, 0.15),
            )
        )
        sigma.append(noise)
        bumps.append([])
    out = []
    for base, noise, groups in zip(scenes, sigma, bumps, strict=True):
        for _ in range(2):
            r = base + rng.normal(0, noise, len(base))
            for bearing, beams, lo, hi in groups:
                i = int(np.searchsorted(angles, bearing)) - beams // 2
                r[i : i + beams] -= rng.uniform(lo, hi, beams)
            out.append(r.astype(np.float32))
            # the same with clutter: single points and pairs
            clutter = rng.random(len(r)) < 0.02
            r[clutter] = rng.uniform(0.5, 3.0, clutter.sum())
            out.append(r.astype(np.float32))
    return out


def _mirror_segment(x, y, s: int, e: int, vec: np.ndarray, params, dalpha: float, st: dict):
    """Segment [s, e) as extract_scan takes it, its steps called one by one (the same calls, the same scratch
    arrays kept from segment to segment in `st`, the accumulator zeroed as far as first needed), with the
    decision and the merges left to the reference: (rp.Decision, the candidate rows after the merges, the
    pairs merged, the kept lines before the decision, the r_acc a circle must beat)."""

    rho_res = vec[FL.FP_RHO_RESOLUTION]
    cos_t, sin_t, acc, toff, idx, lo = st["cos_t"], st["sin_t"], st["acc"], st["toff"], st["idx"], st["lo"]
    sub_s, sub_e, peaks = st["sub_s"], st["sub_e"], st["peaks"]
    nt = cos_t.shape[0]
    nsub = 0
    if e - s >= vec[FL.FP_LINE_MIN_POINTS]:
        HL.normal_cells(x, y, s, e, nt, st["cell"])
        used = nt * HL._bounding_box(x, y, s, e, rho_res, acc.shape[1], st["box"])
        if used > st["zeroed"]:
            acc.reshape(-1)[st["zeroed"] : used] = 0
            st["zeroed"] = used
        nsub = HL.line_subsegments(
            x,
            y,
            s,
            e,
            (acc, toff, st["touched"]),
            cos_t,
            sin_t,
            rho_res,
            int(vec[FL.FP_VOTE_WINDOW] / (np.pi / nt)),
            st["cell"],
            (sub_s, sub_e, peaks),
            st["hist"],
        )
    rows, runs = [], []
    for k in range(nsub):
        t = peaks[k, 1]
        HL.line_of_run(
            x,
            y,
            sub_s[k],
            sub_e[k],
            t * (np.pi / nt),
            toff[t] + (peaks[k, 2] + 0.5) * rho_res,
            peaks[k, 0],
            rho_res,
            idx,
            lo,
        )
        rows.append(lo.copy())
        runs.append((int(sub_s[k]), int(sub_e[k])))
    htl, kept, htl_racc = rp.line_candidates(rows, runs, e - s, params)

    def refit(a: int, b: int, theta: float, rho: float, votes: float) -> np.ndarray:
        HL.line_of_run(x, y, a, b, theta, rho, votes, rho_res, idx, lo)
        return lo.copy()

    def circle(beat: float) -> tuple[np.ndarray, np.ndarray]:
        HC.circle_of_run(x, y, s, e, vec, st["cacc"], idx, st["cout"], beat)
        return st["cout"].copy(), idx[: int(st["cout"][FL.CC_N])].copy()

    pre = (rows, runs, kept, htl, htl_racc)
    kept, rows, _, merged = rp.merge_lines(rows, runs, kept, rho_res, refit)
    st["steps"] = (*pre, kept)
    decision = rp.feature_decision(x, y, s, e, rows, htl, kept, htl_racc, params, dalpha, circle)
    return decision, rows, merged, kept, max(htl_racc, params.line_min_racc)


def _steps_agree(x, y, s: int, e: int, vec, inc: float, d, rows, st: dict, got: tuple, k: int, g: int) -> None:
    """extract_scan's own steps on segment g [s, e) of scan k agree with the reference's (after _mirror_segment,
    which leaves the reference's candidates before the merges in st["steps"]): _merge_lines with rp.merge_lines,
    _circle_case and _circle_wins with the decision d; and
    the row writers write the rows extract_scan wrote (`got`: its line, circle and blob rows of the segment)."""
    pre_rows, runs, pre_kept, htl, htl_racc, kept = st["steps"]
    work = st["work"]
    cand, kept_at, cidx, cout, sub_s, sub_e = work.cand, work.kept, work.cidx, work.cout, work.sub_s, work.sub_e
    if len(pre_kept) > 1:
        cand[: len(pre_rows)] = pre_rows
        kept_at[: len(pre_kept)] = pre_kept
        sub_s[: len(runs)] = [a for a, _ in runs]
        sub_e[: len(runs)] = [b for _, b in runs]
        m = SX._merge_lines(x, y, len(pre_kept), vec[FL.FP_RHO_RESOLUTION], work)
        assert kept_at[:m].tolist() == list(kept), d
        for q in kept:
            np.testing.assert_array_equal(cand[q], rows[q], err_msg=str(d))
    # the HTL part of extract_scan (its candidates, kept lines and merges) is checked through its rows; the steps
    # after it take the reference's candidates
    nkept, ncand, racc = len(kept), len(htl), htl_racc
    cand[: len(rows)] = np.reshape(rows, (len(rows), cand.shape[1]))
    kept_at[:nkept] = kept
    cidx[:ncand] = htl
    tried, leg_only = SX._circle_case(x, y, s, e, vec, ncand, cand, cidx)
    assert tried == d.tried and (not tried or leg_only == d.leg_only), d
    if tried:
        assert SX._circle_wins(x, y, s, e, vec, work, ncand, racc, inc) == (d.kind == "circle"), d
    out = np.full(13, np.nan)
    if d.kind == "circle":
        SX._circle_row(out, k, g, s, e, cout)
        np.testing.assert_array_equal(out[:9], got[1][0])
    elif d.kind == "lines":
        for q in range(nkept):
            SX._line_row(out, k, g, cand[kept_at[q]])
            np.testing.assert_array_equal(out, got[0][q])
    else:
        SX._blob_row(out, x, y, k, g, s, e)
        np.testing.assert_array_equal(out[:9], got[2][0])


def test_extract_scan_decision_equals_the_reference():
    """Every segment of varied scans (two rooms and _feature_scenes; 0.5 and 1 degree steps; default parameters,
    and a larger circle_min_points and line_min_racc) is what the plain decision rule of docs/method.md §5.2
    (rp.line_candidates, rp.merge_lines, rp.feature_decision) makes of the kernel's own HTL candidates and
    circle fit, those computed by the kernels extract_scan calls, called one by one (_mirror_segment): the same
    kind, the lines the kept and merged candidates, the circle the fit, the blob the reference's centroid and
    extent. Each branch of the rule is taken at least once, and some decisions are close."""
    from datmo_cli.perception.params import FeatureParams

    counts: dict[str, int] = {}
    default, strict = FeatureParams(), FeatureParams().replace(circle_min_points=8, line_min_racc=0.8)
    for inc, params in ((np.radians(0.5), default), (np.radians(0.5), strict), (np.radians(1.0), default)):
        angles = -np.pi / 2 + inc * np.arange(int(round(np.pi / inc)) + 1)
        B = len(angles)
        vec = params.kernel_vector()
        nt = int(round(180.0 / params.theta_resolution))
        theta = np.arange(nt) * (np.pi / nt)
        cos_t, sin_t = np.cos(theta), np.sin(theta)
        w = int(round(vec[FL.FP_CIRCLE_WINDOW] / vec[FL.FP_CIRCLE_CELL]))
        width = int(2 * 8.0 / vec[FL.FP_RHO_RESOLUTION]) + 3
        for k, ranges in enumerate(list(_room_scans(2, angles)) + _feature_scenes(angles)):
            segs = rp.segment(ranges, inc, vec[FL.FP_C0], 0.05, 8.0, 1)  # single points and pairs too
            r = np.where(np.isfinite(ranges), ranges, 0.0).astype(np.float64)
            x, y = r * np.cos(angles), r * np.sin(angles)
            # the accumulator as extract_scans leaves it uninitialised: extract_scan zeroes what it uses
            acc = np.full((nt, width), 7, np.int32)
            lines, circles, blobs = _extract_scan_rows(x, y, segs, k, vec, cos_t, sin_t, inc, acc)
            st = {
                "cos_t": cos_t,
                "sin_t": sin_t,
                "acc": np.full((nt, width), 7, np.int32),
                "zeroed": 0,
                "toff": np.empty(nt),
                "idx": np.empty(B, np.int64),
                "lo": np.empty(12),
                "sub_s": np.empty(FL.MAX_SUB, np.int64),
                "sub_e": np.empty(FL.MAX_SUB, np.int64),
                "peaks": np.empty((FL.MAX_SUB, 3), np.int64),
                "cell": np.empty(B, np.int64),
                "touched": np.zeros(nt, np.bool_),
                "hist": np.empty((B, 3), np.int64),
                "box": np.empty(4),
                "cacc": np.zeros((2 * w + 1, 2 * w + 1), np.int32),
                "cout": np.empty(5),
                "work": SX.scan_work(vec, nt, B, 8.0),
            }
            n_lines = n_circles = n_blobs = 0
            for g, (s, e) in enumerate(segs):
                d, rows, merged, kept, beat = _mirror_segment(x, y, s, e, vec, params, inc, st)
                where = f"scan {k} at {np.degrees(inc):.1f} deg, segment {g} [{s}, {e}): {d}"
                got_l, got_c, got_b = (t[t[:, 1] == g] for t in (lines, circles, blobs))
                assert (len(got_c), len(got_l) > 0, len(got_b)) == (
                    d.kind == "circle",
                    d.kind == "lines",
                    d.kind == "blob",
                ), where
                _steps_agree(x, y, s, e, vec, inc, d, rows, st, (got_l, got_c, got_b), k, g)
                if d.kind == "circle":
                    c = d.circle
                    np.testing.assert_array_equal(
                        got_c[0],
                        [k, g, s, e - 1, c[FL.CC_N], c[FL.CC_X], c[FL.CC_Y], c[FL.CC_R], c[FL.CC_RACC]],
                        err_msg=where,
                    )
                elif d.kind == "lines":
                    want = [
                        [
                            k,
                            g,
                            *rows[q][
                                [
                                    FL.LC_FIRST,
                                    FL.LC_LAST,
                                    FL.LC_N,
                                    FL.LC_X0,
                                    FL.LC_Y0,
                                    FL.LC_X1,
                                    FL.LC_Y1,
                                    FL.LC_RHO,
                                    FL.LC_THETA,
                                    FL.LC_LEN,
                                    FL.LC_RACC,
                                ]
                            ],
                        ]
                        for q in d.lines
                    ]
                    np.testing.assert_array_equal(got_l, want, err_msg=where)
                else:
                    np.testing.assert_array_equal(got_b[0][:5], [k, g, s, e - 1, e - s], err_msg=where)
                    np.testing.assert_allclose(
                        got_b[0][FL.B_X : FL.B_SIZE + 1], rp.blob(x[s:e], y[s:e]), rtol=1e-12, atol=1e-12, err_msg=where
                    )
                    assert got_b[0][FL.B_KIND] == (e - s < 3), where
                n_lines += len(d.lines)
                n_circles += d.kind == "circle"
                n_blobs += d.kind == "blob"
                # the branches taken
                lost = d.tried and d.kind != "circle"
                fitted = d.circle is not None and d.circle[FL.CC_N] >= params.circle_min_points
                voted = d.circle is not None and d.circle[FL.CC_RACC] > 0  # refined or not (see circle_of_run)
                for branch, taken in (
                    ("circle, no line", d.kind == "circle" and d.ncand == 0),
                    ("circle, one line", d.kind == "circle" and d.ncand == 1),
                    ("circle, two lines", d.kind == "circle" and d.ncand == 2),
                    ("one line left after a failed circle", lost and d.kind == "lines" and d.ncand == 1),
                    ("perpendicular lines left after a failed circle", lost and d.kind == "lines" and d.ncand == 2),
                    ("lines dropped after a failed circle: a blob", lost and d.kind == "blob" and bool(kept)),
                    ("three lines or more, convex: HTC", d.convex is not None and d.convex >= 2),
                    ("three lines or more, not convex: lines", d.convex is not None and d.convex < 2),
                    ("lines too far apart for a circle", not d.tried and d.kind == "lines"),
                    ("lines merged", bool(merged)),
                    ("blob", d.kind == "blob"),
                    ("under line_min_points", e - s < params.line_min_points),
                    ("under circle_min_points, HTC not run", d.tried and e - s < params.circle_min_points),
                    (
                        "close: the circle's r_acc within 0.05 of what it must beat, ties included",
                        voted and abs(d.circle[FL.CC_RACC] - beat) <= 0.05,
                    ),
                    (
                        "close: the circle beat the lines, not well posed",
                        lost and fitted and d.circle[FL.CC_RACC] > beat,
                    ),
                ):
                    counts[branch] = counts.get(branch, 0) + bool(taken)
            assert (len(lines), len(circles), len(blobs)) == (n_lines, n_circles, n_blobs), f"scan {k}"
    assert all(v > 0 for v in counts.values()), {k: v for k, v in counts.items() if not v}
