"""People: leg pairing, the walking pattern, and person tracks from synthetic leg circles."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.synthetic_features import features_from_lists
from datmo_cli.logs.vocabulary import CLASS_PERSON, MOBILITY_DYNAMIC
from datmo_cli.tracking.measurements import KIND_LEG, KIND_PERSON
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.tracker import Tracker
from tests.reference_tracking import leg_lead, pair_legs, param_vector
from tests.reference_tracking import reference_measurements as measurements

pytestmark = pytest.mark.unit

STEP, WIDTH = 2 * 0.9 * np.sin(np.radians(22)), 0.3  # 2 l sin(theta) and the legs' path distance, m


def walker_legs(t: float, start: tuple[float, float], velocity: tuple[float, float]) -> list[np.ndarray]:
    """The two leg centres (m) at time t (s) of someone walking from `start` at `velocity` (m/s): the
    walking model of docs/method.md §6.1 (one foot down while the other swings a step of 2 l sin theta ahead)."""
    v = np.asarray(velocity, float)
    speed = np.hypot(*v)
    d = v / speed
    n = np.array([-d[1], d[0]])
    u = speed * t
    k = np.floor(u / STEP)
    side = 0.5 if k % 2 == 0 else -0.5
    base = np.asarray(start, float)
    stance = base + d * (k + 0.5) * STEP + n * side * WIDTH
    lifted = base + d * (k - 0.5) * STEP - n * side * WIDTH
    swing = lifted + d * 2 * STEP * (u / STEP - k)
    return [stance, swing]


def run_scene(n_scans: int, objects, params: TrackingParams | None = None, dt: float = 0.2, seed: int = 0):
    """Run a tracker over `objects(t) -> dict of feature lists` (see features_from_lists) and return it with
    each scan's output."""
    rng = np.random.default_rng(seed)
    params = params or TrackingParams()
    tracker = Tracker(params)
    outs = []
    for k in range(n_scans):
        scan = objects(k * dt)
        scan = {
            key: [tuple(np.asarray(v, float) + np.r_[rng.normal(0, 0.01, 2), np.zeros(len(v) - 2)]) for v in vals]
            for key, vals in scan.items()
        }
        feats = features_from_lists([scan])[0]
        outs.append(tracker.step(int(round(k * dt * 1e9)), measurements(feats, params)))
    return tracker, outs


def legs_as_circles(legs: list[np.ndarray]) -> list[tuple[float, float, float]]:
    return [(float(p[0]), float(p[1]), 0.1) for p in legs]


def test_pair_legs_nearest_first_within_the_stride():
    x = np.array([0.0, 0.3, 5.0, 5.5, 9.0])
    y = np.zeros(5)
    a, b, single = pair_legs(x, y, stride_max=0.9)
    assert sorted(zip(a.tolist(), b.tolist(), strict=True)) == [(0, 1), (2, 3)]
    assert single.tolist() == [4]
    # three legs in a row: the nearest two pair, the third stays single
    a, b, single = pair_legs(np.array([0.0, 0.5, 0.7]), np.zeros(3), 0.9)
    assert (a.tolist(), b.tolist(), single.tolist()) == ([1], [2], [0])


def test_leg_lead_sign_alternates_while_walking():
    leads = []
    for t in np.arange(0, 3, 0.2):
        a, b = walker_legs(t, (0, 0), (1.0, 0))
        leads.append(leg_lead(np.array([[*a, *b]]), np.array([1.0]), np.array([0.0]))[0])
    leads = np.array(leads)
    assert (leads > 0.1).any() and (leads < -0.1).any()
    assert np.all(np.abs(leads) <= 2 * STEP)


def test_measurements_pair_legs_at_the_centre_between_them():
    feats = features_from_lists([{"circles": [(2.0, 1.0, 0.1), (2.3, 1.2, 0.1), (5.0, 0.0, 0.3)]}])[0]
    m = measurements(feats, TrackingParams())
    person = np.flatnonzero(m.kind == KIND_PERSON)
    assert len(person) == 1
    assert np.allclose([m.x[person[0]], m.y[person[0]]], [2.15, 1.1], atol=1e-6)
    assert len(m) == 2 and KIND_LEG not in m.kind


def test_walking_legs_make_one_dynamic_person_track_at_their_centre():
    tracker, outs = run_scene(40, lambda t: {"circles": legs_as_circles(walker_legs(t, (1, -3), (0.2, 0.9)))})
    last = outs[-1]
    confirmed = last[last["status"] != 0]
    assert len(confirmed) == 1
    tr = confirmed[0]
    assert tr["classification"] == CLASS_PERSON and tr["mobility"] == MOBILITY_DYNAMIC
    body = np.array([1, -3]) + np.array([0.2, 0.9]) * 39 * 0.2
    assert np.hypot(tr["x"] - body[0], tr["y"] - body[1]) < 0.35
    assert np.hypot(tr["vx"] - 0.2, tr["vy"] - 0.9) < 0.3
    ids = {int(o["id"]) for out in outs[5:] for o in out if o["status"] != 0}
    assert len(ids) == 1


def test_legs_standing_still_are_not_a_walking_person():
    _, outs = run_scene(30, lambda t: {"circles": [(3.0, 0.0, 0.1), (3.0, 0.3, 0.1)]})
    last = outs[-1]
    assert len(last) == 1 and last[0]["classification"] != CLASS_PERSON
    assert last[0]["mobility"] != MOBILITY_DYNAMIC


def test_one_visible_leg_keeps_the_person_alive():
    def scene(t: float) -> dict:
        legs = walker_legs(t, (1, -3), (0, 1.0))
        if 3.0 <= t < 5.0:  # for 2 s one leg hides the other: only one leg is seen
            legs = legs[:1]
        return {"circles": legs_as_circles(legs)}

    _, outs = run_scene(40, scene)
    ids = {int(o["id"]) for out in outs[8:] for o in out if o["status"] != 0}
    assert len(ids) == 1
    assert all(out[out["status"] != 0]["classification"][0] == CLASS_PERSON for out in outs[15:])


def test_pairing_kernel_matches_the_reference():
    from datmo_cli.tracking import _kernels

    rng = np.random.default_rng(5)
    for _ in range(200):
        n = int(rng.integers(0, 9))
        x, y = rng.uniform(0, 3, n), rng.uniform(0, 3, n)
        want = pair_legs(x, y, 0.9)
        got = _kernels.pair_legs(x, y, param_vector(stride_max=0.9))
        assert all(np.array_equal(w, g) for w, g in zip(want, got, strict=True))


def test_side_by_side_walkers_keep_their_own_legs_and_ids():
    """Two people 0.9 m apart walking the same way: nearest-first pairing alone would often pair one's
    leg with the other's; tracks take their own legs first, so each keeps one id."""

    def scene(t: float) -> dict:
        return {
            "circles": legs_as_circles(
                walker_legs(t, (1, 0.0), (0.0, 1.0)) + walker_legs(t + 0.3, (1.9, 0.0), (0.0, 1.0))
            )
        }

    _, outs = run_scene(40, scene)
    conf = [out[out["status"] != 0] for out in outs[6:]]
    ids = {int(i) for c in conf for i in c["id"]}
    assert len(ids) == 2
    assert all(len(c) == 2 and (c["classification"] == CLASS_PERSON).all() for c in conf[5:])
    for i in ids:  # each id stays on its own walker's line, x = 1.0 or 1.9
        xs = np.concatenate([c["x"][c["id"] == i] for c in conf])
        lane = 1.0 if xs[0] < 1.45 else 1.9
        assert np.all(np.abs(xs - lane) < 0.3)


def test_measurement_kinds_and_sizes():
    from datmo_cli.tracking.measurements import KIND_BLOB, KIND_CIRCLE, KIND_RECT

    feats = features_from_lists(
        [
            {
                "circles": [(5.0, 0.0, 0.3)],
                "blobs": [(2.0, 3.0, 0.6)],
                "lines": [(1.0, -1.0, 1.5, -1.0), (3.0, 3.0, 3.1, 3.05), (0.0, 4.0, 3.0, 4.0)],
            }
        ]
    )[0]
    m = measurements(feats, TrackingParams())
    got = sorted(zip(m.kind.tolist(), np.round(m.x, 3).tolist(), np.round(m.y, 3).tolist(), strict=True))
    # the 3 m wall is larger than d_max: no measurement; the 0.11 m line is a leg candidate
    assert got == [(KIND_LEG, 3.05, 3.025), (KIND_CIRCLE, 5.0, 0.0), (KIND_RECT, 1.25, -1.0), (KIND_BLOB, 2.0, 3.0)]
    assert len(m.raw_legs) == 1
