"""People with a leg detector: the measurements of a scan whose legs a detector found, and the person rule
(the detector's evidence over a track's recent hits; walking is not required), against the paper's rule."""

from __future__ import annotations

import numpy as np
from test_tracking_people import walker_legs

from datmo_cli.log.vocabulary import CLASS_CIRCLE_OBJECT, CLASS_PERSON, MOBILITY_DYNAMIC, MOBILITY_STATIC
from datmo_cli.tracking import _kernels
from datmo_cli.tracking.measurements import KIND_BLOB, KIND_CIRCLE, KIND_LEG, KIND_PERSON, KIND_RECT
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.synthetic import features_from_lists
from datmo_cli.tracking.tracker import Tracker
from tests.reference_tracking import param_vector
from tests.reference_tracking import reference_measurements as measurements


def reference_measurements(circles, blobs, lines, legs, stride_max, d_max, weak=None):
    """Plain Python: legs paired (nearest pairs first, within the stride) or single; every other segment as
    its circle, its lines' bounding box or its blob, with its leg probability from `weak` ({segment: p}, else
    0); nothing larger than d_max. Rows (kind, x, y, size, probability; 0 for legs)."""
    weak = weak or {}
    rows = []
    free = list(range(len(legs)))
    pairs = sorted((np.hypot(legs[i][1] - legs[j][1], legs[i][2] - legs[j][2]), i, j)
                   for i in free for j in free if i < j)
    used = set()
    for d, i, j in pairs:
        if d <= stride_max and i not in used and j not in used:
            used |= {i, j}
            rows.append((KIND_PERSON, 0.5 * (legs[i][1] + legs[j][1]), 0.5 * (legs[i][2] + legs[j][2]),
                         d + 0.5 * (legs[i][3] + legs[j][3]), 0.0))
    for i in free:
        if i not in used:
            rows.append((KIND_LEG, legs[i][1], legs[i][2], legs[i][3], 0.0))
    leg_segments = {g[0] for g in legs}
    for seg, x, y, r in circles:
        if seg not in leg_segments:
            rows.append((KIND_CIRCLE, x, y, 2 * r, weak.get(seg, 0.0)))
    for seg, x, y, size in blobs:
        if seg not in leg_segments:
            rows.append((KIND_BLOB, x, y, size, weak.get(seg, 0.0)))
    for seg in sorted({li[0] for li in lines} - leg_segments):
        pts = np.array([[li[1], li[2]] for li in lines if li[0] == seg] + [[li[3], li[4]] for li in lines
                                                                            if li[0] == seg])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        rows.append((KIND_RECT, *(0.5 * (lo + hi)), float(np.hypot(*(hi - lo))), weak.get(seg, 0.0)))
    return sorted((k, round(x, 9), round(y, 9), round(s, 9), round(p, 9)) for k, x, y, s, p in rows if s <= d_max)


f8, i8 = np.float64, np.int64


def test_learned_measurements_match_the_reference():
    rng = np.random.default_rng(3)
    for _ in range(40):
        n = rng.integers(0, 12)
        segs = rng.permutation(30)[:n]
        kinds = rng.integers(0, 4, n)   # 0 circle, 1 blob, 2 line(s), 3 a detected leg (also given as a circle)
        circles, blobs, lines, legs = [], [], [], []
        for seg, kind in zip(segs.tolist(), kinds.tolist(), strict=True):
            x, y = rng.uniform(-5, 5, 2)
            if kind == 0:
                circles.append((seg, x, y, rng.uniform(0.05, 0.5)))
            elif kind == 1:
                blobs.append((seg, x, y, rng.uniform(0.05, 2.0)))
            elif kind == 2:
                for _ in range(rng.integers(1, 3)):
                    lines.append((seg, x, y, x + rng.uniform(-1, 1), y + rng.uniform(-1, 1)))
            else:
                circles.append((seg, x, y, 0.08))
                legs.append((seg, x, y, rng.uniform(0.05, 0.2)))
        others = sorted(set(segs.tolist()) - {g[0] for g in legs})
        weak = {seg: float(rng.uniform(0.05, 0.5)) for seg in others if rng.random() < 0.5}

        def col(rows, k, t=f8):
            return np.array([r[k] for r in rows], t)

        def beams(rows, width=5):
            return col(rows, 0, i8) * 10, col(rows, 0, i8) * 10 + width

        ws = np.array(list(weak), i8)
        got = _kernels.learned_measurements(
            *beams(circles), col(circles, 1), col(circles, 2), col(circles, 3),
            *beams(blobs), col(blobs, 1), col(blobs, 2), col(blobs, 3),
            col(lines, 0, i8), *beams(lines, 2), col(lines, 1), col(lines, 2), col(lines, 3), col(lines, 4),
            *beams(legs), col(legs, 1), col(legs, 2), col(legs, 3), ws * 10, ws * 10 + 5,
            np.array(list(weak.values()), f8), param_vector(stride_max=0.9, d_max=1.5))
        x, y, size, kind, _, prob = got
        rows = sorted((int(k), round(float(a), 9), round(float(b), 9), round(float(s), 9), round(float(p), 9))
                      for k, a, b, s, p in zip(kind, x, y, size, prob, strict=True))
        assert rows == reference_measurements(circles, blobs, lines, legs, 0.9, 1.5, weak)


def _run(scans: list[dict], learned: bool, dt: float = 0.1) -> list[np.ndarray]:
    params = TrackingParams()
    tracker = Tracker(params, learned=learned)
    feats = features_from_lists(scans)
    return [tracker.step(int(round(k * dt * 1e9)), measurements(f, params, learned)) for k, f in enumerate(feats)]


def _final(outs: list[np.ndarray]) -> np.ndarray:
    last = outs[-1]
    return last[last["status"] != 0]


def test_a_person_standing_still_is_a_static_person_with_a_detector():
    rng = np.random.default_rng(0)
    scans = [{"legs": [(2.0 + rng.normal(0, 0.01), 0.15, 0.12), (2.0 + rng.normal(0, 0.01), -0.15, 0.12)]}
             for _ in range(30)]
    out = _final(_run(scans, learned=True))
    assert len(out) == 1
    assert out["classification"][0] == CLASS_PERSON
    assert out["mobility"][0] == MOBILITY_STATIC
    # the paper's rule needs the walking pattern: the same legs as circles are not a person
    paper = _final(_run([{"circles": [(x, y, 0.06) for x, y, _ in s["legs"]]} for s in scans], learned=False))
    assert len(paper) == 1 and paper["classification"][0] != CLASS_PERSON


def test_one_leg_whose_partner_is_hidden_is_a_person():
    both = [{"legs": [(3.0, 1.15, 0.12), (3.0, 0.85, 0.12)]} for _ in range(10)]
    one = [{"legs": [(3.0, 1.15 + 0.01 * (k % 2), 0.12)]} for k in range(20)]
    out = _final(_run(both + one, learned=True))
    assert len(out) == 1 and out["classification"][0] == CLASS_PERSON


def test_a_lone_still_leg_never_seen_with_its_partner_is_not_a_person():
    # a table leg or a door frame the detector likes: standing people show two legs now and then
    out = _final(_run([{"legs": [(3.0, 1.0 + 0.01 * (k % 2), 0.12)]} for k in range(30)], learned=True))
    assert len(out) == 1 and out["classification"][0] != CLASS_PERSON


def test_something_the_moving_scanner_carries_is_not_a_person():
    # a part of the robot seen by its own scanner: fixed in the sensor frame while the robot drives 3 m
    params = TrackingParams()
    tracker = Tracker(params, learned=True)
    feats = features_from_lists([{"legs": [(0.6, 0.15, 0.12), (0.6, -0.15, 0.12)]}] * 30)
    for k, f in enumerate(feats):
        out = tracker.step(int(k * 1e8), measurements(f, params, True), pose=np.array([0.1 * k, 0.0, 0.0]))
    assert len(out) == 1 and out["classification"][0] != CLASS_PERSON


def test_a_walking_person_is_a_dynamic_person():
    scans = [{"legs": [(float(p[0]), float(p[1]), 0.12) for p in walker_legs(0.1 * k, (1.0, -3.0), (0.3, 1.0))]}
             for k in range(60)]
    out = _final(_run(scans, learned=True))
    people = out[out["classification"] == CLASS_PERSON]
    assert len(people) == 1 and people["mobility"][0] == MOBILITY_DYNAMIC


def test_small_circles_the_detector_rejects_are_not_people():
    scans = [{"circles": [(2.0, 1.0, 0.06), (2.3, 1.0, 0.06)]} for _ in range(30)]
    out = _final(_run(scans, learned=True))
    assert len(out) >= 1
    assert not (out["classification"] == CLASS_PERSON).any()
    assert (out["classification"] == CLASS_CIRCLE_OBJECT).all()


def test_person_evidence_fades_when_the_detector_stops_seeing_legs():
    legs = [{"legs": [(2.0, 0.15, 0.12), (2.0, -0.15, 0.12)]} for _ in range(20)]
    blobs = [{"blobs": [(2.0, 0.0, 0.12)]} for _ in range(20)]
    outs = _run(legs + blobs, learned=True)
    first = outs[19][outs[19]["status"] != 0]
    assert first["classification"][0] == CLASS_PERSON
    last = _final(outs)
    assert len(last) == 1 and last["id"][0] == first["id"][0]
    assert last["classification"][0] != CLASS_PERSON
