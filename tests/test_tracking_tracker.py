"""The tracker's life cycle: confirmation, coasting, occlusion-aware deletion, time from stamps, world frame."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.synthetic_features import features_from_lists
from datmo_cli.logs.scan import ScanGeometry
from datmo_cli.logs.vocabulary import STATUS_COASTING, STATUS_CONFIRMED, STATUS_TENTATIVE
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.tracker import Tracker
from tests.reference_tracking import background_update, param_vector
from tests.reference_tracking import reference_measurements as measurements

pytestmark = pytest.mark.unit

GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0)
P = TrackingParams()


def meas(*circles):
    return measurements(features_from_lists([{"circles": list(circles)}])[0], P)


NONE = meas()
NO_PEOPLE = np.zeros(0)  # no person's returns to leave out of the background grid


def free_ranges() -> np.ndarray:
    return np.full(GEOM.n_beams, 7.5, np.float32)


@settings(max_examples=30, deadline=None)
@given(hits=st.lists(st.booleans(), min_size=1, max_size=12))
def test_never_confirmed_before_m_hits_in_the_window(hits: list[bool]):
    tracker = Tracker(P, GEOM)
    seen = 0
    window: list[bool] = []
    for k, hit in enumerate(hits):
        out = tracker.step(k * 200_000_000, meas((3.0, 0.0, 0.3)) if hit or k == 0 else NONE, free_ranges())
        seen += hit or k == 0
        window = (window + [hit or k == 0])[-P.confirm_window :]
        if len(out) and out[0]["status"] != STATUS_TENTATIVE:
            assert seen >= P.confirm_hits


def test_one_scan_never_confirms_and_m_of_n_does():
    tracker = Tracker(P, GEOM)
    out = tracker.step(0, meas((3.0, 0.0, 0.3)), free_ranges())
    assert out["status"].tolist() == [STATUS_TENTATIVE]
    out = tracker.step(200_000_000, meas((3.0, 0.0, 0.3)), free_ranges())
    assert out["status"].tolist() == [STATUS_TENTATIVE]
    out = tracker.step(400_000_000, meas((3.0, 0.0, 0.3)), free_ranges())
    assert out["status"].tolist() == [STATUS_CONFIRMED]
    assert out["hits"].tolist() == [3] and out["age"].tolist() == [3]


def _lifetime(occluder: bool) -> float:
    """Seconds a confirmed track at (4, 0) survives after its last hit, with or without a nearer return
    covering its bearing."""
    tracker = Tracker(P, GEOM)
    for k in range(5):
        tracker.step(k * 200_000_000, meas((4.0, 0.0, 0.3)), free_ranges())
    ranges = free_ranges()
    if occluder:
        ranges[175:186] = 2.0  # something at 2 m straight ahead
    k = 5
    while True:
        out = tracker.step(k * 200_000_000, NONE, ranges)
        if not len(out):
            return (k - 4) * 0.2
        assert out["status"][0] == STATUS_COASTING
        assert out["occluded"][0] == occluder
        assert out["misses"][0] == k - 4
        k += 1


def test_occluded_tracks_live_longer_than_missed_ones():
    seen, hidden = _lifetime(False), _lifetime(True)
    assert seen == pytest.approx(P.delete_after + 0.2, abs=0.21)
    assert hidden == pytest.approx(P.delete_after_occluded + 0.2, abs=0.21)
    assert hidden > seen


def test_out_of_view_counts_as_occluded():
    tracker = Tracker(P, GEOM)
    for k in range(5):
        tracker.step(k * 200_000_000, meas((-2.0, 0.5, 0.3)), free_ranges())  # behind the scanner
    out = tracker.step(5 * 200_000_000, NONE, free_ranges())
    assert out["occluded"].tolist() == [1]


def test_time_comes_from_stamps_uneven_rates_and_dropped_scans():
    rng = np.random.default_rng(1)
    times = np.cumsum(rng.choice([0.05, 0.1, 0.2, 0.6], 60))  # uneven, with gaps like dropped scans
    tracker = Tracker(P, GEOM)
    for t in times:
        out = tracker.step(int(t * 1e9), meas((1.0 + 0.5 * t, -2.0 + 0.25 * t, 0.3)), free_ranges())
    assert len({int(i) for i in out["id"]}) == 1
    assert out["vx"][0] == pytest.approx(0.5, abs=0.05)
    assert out["vy"][0] == pytest.approx(0.25, abs=0.05)


def test_world_frame_with_a_moving_sensor():
    """A still object seen from a sensor driving and turning stays still in the world frame."""
    tracker = Tracker(P, GEOM)
    obj = np.array([5.0, 1.0])
    for k in range(30):
        t = 0.2 * k
        pose = np.array([0.3 * t, 0.1 * t, 0.2 * t])
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = obj - pose[:2]
        local = (c * d[0] + s * d[1], -s * d[0] + c * d[1])
        out = tracker.step(int(t * 1e9), meas((*local, 0.3)), free_ranges(), pose)
    tr = out[0]
    assert np.allclose([tr["world_x"], tr["world_y"]], obj, atol=0.02)
    assert np.hypot(tr["world_vx"], tr["world_vy"]) < 0.05
    assert np.allclose([tr["x"], tr["y"]], local, atol=0.02)
    assert tr["mobility"] == 0  # static


def test_no_world_fields_without_odometry():
    tracker = Tracker(P, GEOM)
    out = tracker.step(0, meas((3.0, 0.0, 0.3)), free_ranges())
    assert np.isnan(out["world_x"]).all() and np.isnan(out["world_vy"]).all()
    assert out["covariance"].shape == (1, 16)


def test_two_crossing_tracks_keep_their_ids():
    tracker = Tracker(P, GEOM)
    for k in range(40):
        t = 0.2 * k
        a = (1.0 + 0.8 * t, -2.0 + 0.5 * t, 0.3)
        b = (1.0 + 0.8 * t, 2.0 - 0.5 * t, 0.3)
        out = tracker.step(int(t * 1e9), meas(a, b), free_ranges())
        if k == 10:
            first = {int(i): float(y) for i, y in zip(out["id"], out["y"], strict=True)}
    final = {int(i): float(y) for i, y in zip(out["id"], out["y"], strict=True)}
    assert set(final) == set(first)
    for i in first:  # each id kept its side's motion through the crossing at t = 4 s
        assert np.sign(final[i]) == -np.sign(first[i])


def test_a_track_lost_out_of_view_is_reacquired_with_its_id():
    """Someone walks out of the field of view (behind the scanner), turns while hidden and comes back
    elsewhere: constant-velocity prediction cannot follow, reacquisition by reachable distance does."""
    tracker = Tracker(P, GEOM)
    t = 0.0
    for _ in range(10):  # walking -x at y = 2 towards the edge of view (x = 0)
        out = tracker.step(int(t * 1e9), meas((1.5 - 0.8 * t, 2.0, 0.3)), free_ranges())
        t += 0.2
    first = int(out["id"][out["status"] != STATUS_TENTATIVE][0])
    for _ in range(15):  # 3 s out of view (x < 0)
        out = tracker.step(int(t * 1e9), NONE, free_ranges())
        t += 0.2
    assert out["occluded"].all()
    for k in range(5):  # reappears 1.5 m from where it was lost, walking +x
        out = tracker.step(int(t * 1e9), meas((0.2 + 0.16 * k, 0.5, 0.3)), free_ranges())
        t += 0.2
    assert [int(i) for i in out["id"]] == [first]


def test_duplicate_leg_tracks_merge_into_the_older():
    tracker = Tracker(P, GEOM)
    for k in range(6):
        tracker.step(k * 200_000_000, meas((3.0, 0.0, 0.1), (3.0, 0.3, 0.1)), free_ranges())
    # the legs spread beyond the stride bound: one pair becomes two single legs 1 m apart, then closes
    out = tracker.step(6 * 200_000_000, meas((3.0, -0.35, 0.1), (3.0, 0.65, 0.1)), free_ranges())
    for k in range(7, 12):
        out = tracker.step(k * 200_000_000, meas((3.0, 0.0, 0.1), (3.0, 0.3, 0.1)), free_ranges())
    assert len(out) == 1


def test_a_lost_person_takes_back_a_tentative_track_started_on_them():
    """Someone coming back into view shows their legs as one wide arc first (a circle no lost track of legs may be
    reacquired on): a tentative track starts on it and then takes the pair of legs; the person's own lost track
    must take them back, keeping its id."""
    tracker = Tracker(P, GEOM)
    t = 0.0
    for _ in range(15):  # walking -x at y = 2 towards the edge of view (x = 0)
        x = 2.5 - 0.8 * t
        out = tracker.step(int(t * 1e9), meas((x, 1.85, 0.1), (x - 0.3 * np.cos(6 * t), 2.15, 0.1)), free_ranges())
        t += 0.2
    first = out[out["status"] != STATUS_TENTATIVE]
    assert len(first) == 1 and first["mobility"][0] == 1
    for _ in range(10):  # 2 s out of view
        out = tracker.step(int(t * 1e9), NONE, free_ranges())
        t += 0.2
    out = tracker.step(int(t * 1e9), meas((0.3, 1.0, 0.25)), free_ranges())  # one wide arc: a tentative track
    t += 0.2
    assert len(out) == 2
    for k in range(5):  # then both legs, walking +x
        x = 0.35 + 0.16 * k
        out = tracker.step(int(t * 1e9), meas((x, 0.85, 0.1), (x + 0.2, 1.15, 0.1)), free_ranges())
        t += 0.2
    assert [int(i) for i in out["id"]] == [int(first["id"][0])]


def test_background_grid_marks_long_hit_places_and_forgets_places_seen_through():
    """A place hit for longer than background_time is background; once a beam passes beyond it, it is not."""
    from datmo_cli.tracking import _kernels

    n, cell = 100, 0.1
    score, mark = np.zeros(n * n), np.full(n * n, -1, np.int64)
    active = np.zeros(1000, np.int64)
    angles = np.radians([-1.0, 0.0, 1.0])
    wall = np.array([3.0, 3.0, 3.0], np.float32)

    def update(count: int, scan: int, ranges: np.ndarray) -> int:
        return background_update(
            score, mark, active, count, scan, ranges, np.cos(angles), np.sin(angles), angles[0],
            angles[1] - angles[0], 0.0, 8.0, 0.0, 0.0, 1.0, 0.0, 0.2, -5.0, -5.0, cell, n, 0.3, 6.0,
            NO_PEOPLE, NO_PEOPLE, 0.4,
        )  # fmt: skip

    def on_background_at_3m() -> bool:
        params = param_vector(background_cell=cell, background_time=3.0)
        xs, zero = np.array([3.0]), np.array([0.0])
        return bool(_kernels.on_background(score, xs, zero, zero, 0.0, 0.0, -5.0, -5.0, n, params)[0])

    count = 0
    for scan in range(1, 21):  # 4 s at 5 Hz
        count = update(count, scan, wall)
    assert on_background_at_3m()
    gone = np.array([6.0, 6.0, 6.0], np.float32)  # the object left: the beams now reach 6 m
    update(count, 21, gone)
    assert not on_background_at_3m()


def test_a_duplicate_yields_to_the_person_whatever_its_hits():
    """Two confirmed leg/person tracks moving alike within merge_distance are one: the one that goes is
    not the person, even when the other (e.g. a track on a bench's pieces uncovered by the person walking
    past) has more hits; between two unknowns, the one with fewer hits goes."""
    from datmo_cli.logs.vocabulary import CLASS_PERSON, CLASS_UNKNOWN, MOBILITY_DYNAMIC, MOBILITY_STATIC
    from datmo_cli.tracking import _life_cycle, state
    from datmo_cli.tracking.measurements import KIND_LEG, KIND_PERSON

    def tracks(cls, mobility, hits):
        t = state.TrackTable(P.tail_length, capacity=2)
        t.n = 2
        tab = t.table
        tab[:, state.X : state.X + 4] = [[2.0, 1.0, 0.8, 0.0], [2.0, 1.0 + 0.5 * P.merge_distance, 0.8, 0.0]]
        tab[:, state.VOTES + KIND_PERSON] = 5
        tab[:, state.VOTES + KIND_LEG] = 5
        tab[:, state.CONFIRMED] = 1
        tab[:, state.CLS] = cls
        tab[:, state.MOBILITY] = mobility
        tab[:, state.HITS] = hits
        return tab

    prm = P.kernel_vector()
    person_fewer_hits = tracks([CLASS_PERSON, CLASS_UNKNOWN], [MOBILITY_DYNAMIC, MOBILITY_STATIC], [40, 80])
    unknowns = tracks([CLASS_UNKNOWN, CLASS_UNKNOWN], [MOBILITY_STATIC, MOBILITY_STATIC], [40, 80])
    dynamic_first = tracks([CLASS_UNKNOWN, CLASS_UNKNOWN], [MOBILITY_DYNAMIC, MOBILITY_STATIC], [40, 80])
    for learned in (False, True):
        assert _life_cycle.duplicates(person_fewer_hits, 2, learned, prm).tolist() == [False, True]
        assert _life_cycle.duplicates(unknowns, 2, learned, prm).tolist() == [True, False]
        assert _life_cycle.duplicates(dynamic_first, 2, learned, prm).tolist() == [False, True]
