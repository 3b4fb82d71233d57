"""People, round 3: a track out of view is apart from a hidden one (delete_after_out_of_view), leg-like clutter
standing still from the start is not promoted with the free-space test on (its legs were never seen in free space),
the background never takes the returns of a track of background_shield evidence, a person keeps to its legs, and a
jump at re-acquisition is no velocity (restart_jump)."""

from __future__ import annotations

import numpy as np
import pytest
from test_tracking_learned import GEOM, LEG_R, THR, new_tracker, ranges, scan, standing, tracked

from datmo_cli.logs.vocabulary import CLASS_CIRCLE_OBJECT, CLASS_PERSON
from datmo_cli.tracking import _association, _kernels, _people, state
from datmo_cli.tracking._scan_measurements import K_BLOB, K_CIRCLE
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.tracker import _COMPAT_LEARNED
from tests import reference_tracking as rt

pytestmark = pytest.mark.unit

P = TrackingParams()
FREE = TrackingParams(free_space_scans=8)  # the free-space test on (off by default: see docs/legs.md)
DT = 100_000_000  # ns between scans (10 Hz)


# ------------------------------------------------------------------------------- out of view, hidden
def _last_seen(turn: bool, hide: bool, params: TrackingParams = P) -> dict[int, tuple[int, float]]:
    """A person (legs p 0.95) and a circle object seen for 1.5 s; then the scanner turns its back on them
    (`turn`), or a nearer return hides them (`hide`), or neither (nothing there). {id: (class, s it lived
    unseen)}."""
    tracker = new_tracker(params)
    legs = standing(2.0, 0.5, 0.95, 0)
    things = [(x, y, LEG_R) for x, y, _ in legs] + [(3.0, -1.5, 0.3)]
    for k in range(15):
        tracker.step(k * DT, scan(legs, circles=[(3.0, -1.5, 0.3)]), ranges(things), np.zeros(3))
    out = tracker.output()
    cls = {int(i): int(c) for i, c in zip(out["id"], out["classification"], strict=True)}
    last: dict[int, int] = {}
    for k in range(15, 130):
        pose = np.array([0.0, 0.0, np.pi if turn else 0.0])
        walls = [(1.0, 0.25, 0.2), (1.0, -0.5, 0.2)] if hide else []
        out = tracker.step(k * DT, scan(), ranges(walls), pose)
        for i in out["id"].tolist():
            last[int(i)] = k
    return {i: (cls[i], 0.1 * (last.get(i, 14) - 14)) for i in cls}


@pytest.mark.parametrize("out_of_view", [0.8, 5.0])
def test_a_track_out_of_view_lives_delete_after_out_of_view_a_person_person_coast_at_least(out_of_view: float):
    lived = _last_seen(turn=True, hide=False, params=TrackingParams(delete_after_out_of_view=out_of_view))
    assert sorted(c for c, _ in lived.values()) == sorted([CLASS_PERSON, CLASS_CIRCLE_OBJECT])
    for cls, s in lived.values():
        limit = max(out_of_view, P.person_coast) if cls == CLASS_PERSON else out_of_view
        assert limit - 0.05 <= s <= limit + 0.15, (cls, s)


def test_a_track_hidden_behind_a_nearer_return_still_coasts_delete_after_occluded():
    for cls, s in _last_seen(turn=False, hide=True).values():
        assert s >= min(P.delete_after_occluded, 11.0) - 0.15, (cls, s)


# ---------------------------------------------------------------------------------------- free space
def _clutter_then_walker(p: float) -> tuple[list[list[int]], list[list[int]]]:
    """Leg-like clutter (a pair the detector scores p) standing at (2, 0.5) from the start, and someone (legs
    scored p) walking in from (5, -3) to (4, 1) and standing there; ranges of both. The classes of the confirmed
    tracks near each, per scan."""
    tracker = new_tracker(FREE)
    clutter, near_c, near_w = standing(2.0, 0.5, p, 0), [], []
    for k in range(120):
        t = min(0.1 * k, 4.0)
        cx, cy = 5.0 - 0.25 * t, -3.0 + t
        walker = standing(cx, cy, p, k)
        legs = clutter + walker
        out = tracker.step(k * DT, scan(legs), ranges([(x, y, LEG_R) for x, y, _ in legs], wall=7.5), np.zeros(3))
        near_c.append(tracked(out, (2.0, 0.5))["classification"].tolist())
        near_w.append(tracked(out, (cx, cy))["classification"].tolist())
    return near_c, near_w


def test_legs_standing_still_from_the_start_are_no_person_until_person_evidence_unfree():
    near_c, near_w = _clutter_then_walker(0.7)  # person_evidence <= 0.7 < person_evidence_unfree
    assert not any(CLASS_PERSON in c for c in near_c)
    assert all(c == [CLASS_PERSON] for c in near_w[60:])  # seen where the scanner saw through: a person, standing too
    near_c, _ = _clutter_then_walker(0.95)  # beyond doubt: a person standing there from the start
    assert all(c == [CLASS_PERSON] for c in near_c[10:])


def test_in_free_space_equals_the_reference():
    rng = np.random.default_rng(3)
    prm = P.kernel_vector(THR)
    geo = np.array([GEOM.angle_min, GEOM.angle_increment, GEOM.range_max, 1.0, GEOM.range_min])
    for _ in range(100):
        K = int(rng.integers(0, 6))
        kept = np.zeros((K, GEOM.n_beams), np.float32)
        for i in range(K):
            kept[i] = ranges([(*rng.uniform(0.5, 4, 2), 0.2)], wall=rng.uniform(2, 8))
        poses = np.c_[rng.normal(0, 0.3, (K, 2)), rng.normal(0, 0.2, K)]
        x, y = rng.uniform(-1, 5, 2)
        got = _people.in_free_space(x, y, kept, poses, K, geo, prm)
        g = GEOM
        want = rt.in_free_space(x, y, kept, poses, g.angle_min, g.angle_increment, g.range_min, g.range_max, P)
        assert got == want


def test_owns_returns_people_and_tracks_of_background_shield_evidence():
    tab = np.zeros((4, state.n_columns(1)))
    tab[0, state.IS_PERSON] = 1.0
    tab[1:, state.LEG_HITS] = 5
    tab[1:, state.LEG_SCORE] = [P.background_shield, P.background_shield - 0.01, 0.0]
    prm = P.kernel_vector(THR)
    assert [_people.owns_returns(tab, k, prm) for k in range(4)] == [True, True, False, False]


def test_in_free_space_needs_scans_that_saw_through_the_place():
    prm = P.kernel_vector(THR)
    geo = np.array([GEOM.angle_min, GEOM.angle_increment, GEOM.range_max, 1.0, GEOM.range_min])
    kept = np.stack([ranges([(2.0, 0.0, 0.1)]), ranges([(2.0, 0.0, 0.1)]), ranges(wall=5.0)])
    poses = np.zeros((3, 3))
    assert not _people.in_free_space(2.0, 0.0, kept[:2], poses[:2], 2, geo, prm)  # always hit there
    assert not _people.in_free_space(2.0, 0.0, kept[2:], poses[2:], 1, geo, prm)  # seen through once: not enough
    assert _people.in_free_space(2.0, 0.0, np.stack([kept[2], kept[2]]), poses[:2], 2, geo, prm)
    assert _people.in_free_space(4.0, 1.0, kept, poses, 3, geo, prm)


# ------------------------------------------------------------------------------------- the evidence
def test_the_background_never_takes_the_returns_of_a_track_of_high_evidence():
    """Legs scored 0.7 (not a person: standing from the start) in front of a wall for 8 s (background_time 3 s):
    their places never become background, the wall does."""
    tracker = new_tracker(TrackingParams(free_space_scans=8, background_shield=0.6))
    legs = [(2.0, 0.5 + d) for d in (0.15, -0.15)]
    for k in range(80):
        tracker.step(k * DT, scan([(x, y, 0.7) for x, y in legs]), ranges([(x, y, LEG_R) for x, y in legs], wall=5.0))
    score = tracker._bg[0]
    n = int(np.sqrt(len(score)) + 0.5)
    places = np.array([[x - LEG_R, y] for x, y in legs] + [[5.0, 0.5]])
    on = _kernels.on_background(
        score,
        places[:, 0].copy(),
        places[:, 1].copy(),
        np.zeros(3),
        0.0,
        0.0,
        tracker._ctx[state.C_BG_X0],
        tracker._ctx[state.C_BG_Y0],
        n,
        P.kernel_vector(THR),
    )
    np.testing.assert_array_equal(on, [False, False, True])


# ---------------------------------------------------------------------------------- holding a person
def _one_track(person: bool, misses: int = 0) -> np.ndarray:
    tab = np.zeros((1, state.n_columns(1)))
    tab[0, state.X], tab[0, state.Y], tab[0, state.VX] = 2.0, 0.0, 1.0
    for i in (0, 5):
        tab[0, state.P0 + i] = 0.3**2
    for i in (10, 15):
        tab[0, state.P0 + i] = 0.5**2
    tab[0, state.CONFIRMED] = tab[0, state.HITS] = 1.0
    tab[0, state.IS_PERSON] = 1.0 if person else 0.0
    tab[0, state.VOTES + K_BLOB] = 0.0 if person else 5.0
    tab[0, state.MISSES] = misses
    return tab


def test_a_person_whose_legs_are_there_takes_no_segment_beside_them():
    prm = P.kernel_vector(THR)
    mx, my = np.array([2.0]), np.array([0.45])  # a blob 0.45 m beside, no leg probability
    mkind, mprob = np.array([K_BLOB]), np.zeros(1)
    raw = np.array([[2.0, 0.05, 0.12, 0.3, -1.0]])  # a weak leg candidate at the person's place
    crow = np.zeros(1, np.int64)
    none = np.zeros(0, np.int64)
    rows, _ = _association.associate(_one_track(True), 1, mx, my, mkind, mprob, raw, none, _COMPAT_LEARNED, crow, prm)
    assert len(rows) == 0
    ok = np.ones((1, 1), np.bool_)
    _association.hold_people(ok, _one_track(True), 1, mkind, mprob, raw, prm)
    assert not ok[0, 0]
    # no leg candidate near: it may take it (someone whose legs the detector missed); a track of blobs may too
    far = raw + np.array([[3.0, 3.0, 0, 0, 0]])
    rows, _ = _association.associate(_one_track(True), 1, mx, my, mkind, mprob, far, none, _COMPAT_LEARNED, crow, prm)
    assert len(rows) == 1
    crow3 = np.full(1, 3, np.int64)
    rows, _ = _association.associate(_one_track(False), 1, mx, my, mkind, mprob, raw, none, _COMPAT_LEARNED, crow3, prm)
    assert len(rows) == 1


@pytest.mark.parametrize(("misses", "offset", "restarted"), [(3, 1.2, True), (0, 1.2, False), (3, 0.5, False)])
def test_a_jump_of_more_than_a_stride_at_reacquisition_sets_no_velocity(misses: int, offset: float, restarted: bool):
    tab = _one_track(True, misses)
    prm = TrackingParams(restart_jump=0.9).kernel_vector(THR)
    one, kind, legs = np.zeros(1, np.int64), np.array([K_CIRCLE]), np.full((1, 4), np.nan)
    _association.update(tab, 1, one, one, np.array([2.0]), np.array([offset]), kind, np.zeros(1), legs, prm)
    speed = np.hypot(tab[0, state.VX], tab[0, state.VY])
    if restarted:  # at the measurement, without velocity
        assert (tab[0, state.X], tab[0, state.Y], speed) == pytest.approx((2.0, offset, 0.0), abs=1e-9)
    else:  # a Kalman update: part of the way, the velocity kept and corrected
        assert tab[0, state.Y] < offset and speed > 0.5
