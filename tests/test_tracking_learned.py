"""People with a leg detector: the measurements of a scan whose leg candidates a detector scored, and
the person life cycle on small synthetic scenes: a person is promoted once from paired legs and kept until the
evidence (moved only by leg-candidate hits) falls below person_maintain, coasts person_coast s flagged occluded,
never feeds the background, takes weak legs above person_maintain; candidates on beams the robot carries are no
legs; `datmo track` takes the leg threshold a features log records; the removed keys are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from test_tracking_people import walker_legs

from benchmarks.synthetic_features import BLOB_DTYPE, CIRCLE_DTYPE, LEG_DTYPE, LINE_DTYPE, features_from_lists
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    MOBILITY_DYNAMIC,
    MOBILITY_STATIC,
    STATUS_COASTING,
)
from datmo_cli.tracking import _kernels, state
from datmo_cli.tracking.bundles import Blobs, Circles, Legs, Lines
from datmo_cli.tracking.measurements import KIND_BLOB, KIND_CIRCLE, KIND_LEG, KIND_PERSON, KIND_RECT, ScanFeatures
from datmo_cli.tracking.params import TrackingParams
from datmo_cli.tracking.tracker import Tracker
from tests.reference_tracking import param_vector
from tests.reference_tracking import reference_measurements as measurements

pytestmark = pytest.mark.cli

P = TrackingParams()
THR = 0.8  # the leg threshold of these scenes (about the shipped model's)


# ------------------------------------------------------------------------------------- measurements
def overlap(a: tuple[int, int], b: tuple[int, int]) -> int:
    """Beams two inclusive beam ranges share."""
    return min(a[1], b[1]) - max(a[0], b[0]) + 1


def reference_measurements(circles, blobs, lines, legs, weak, stride_max, d_max):
    """Plain Python: legs (first, last, x, y, width) paired (nearest pairs first, within the stride) or single;
    every circle (first, last, x, y, r), blob (first, last, x, y, size) and segment of lines (segment, first,
    last, x0, y0, x1, y1) on no leg's beams as its circle, its lines' bounding box or its blob, with the largest
    leg probability of the weak candidates (first, last, p) sharing a beam with it (else 0); nothing larger than
    d_max. Returns rows (kind, x, y, size, probability; 0 for legs), sorted, and per weak candidate the row of
    the measurement sharing most beams with it (the first made on ties: circles, blobs, then segments in
    order), None when none does or that one is larger than d_max."""
    rows = []
    pairs = sorted(
        (np.hypot(legs[i][2] - legs[j][2], legs[i][3] - legs[j][3]), i, j)
        for i in range(len(legs))
        for j in range(len(legs))
        if i < j
    )
    used = set()
    for d, i, j in pairs:
        if d <= stride_max and i not in used and j not in used:
            used |= {i, j}
            rows.append(
                (
                    KIND_PERSON,
                    0.5 * (legs[i][2] + legs[j][2]),
                    0.5 * (legs[i][3] + legs[j][3]),
                    d + 0.5 * (legs[i][4] + legs[j][4]),
                    0.0,
                )
            )
    rows += [(KIND_LEG, g[2], g[3], g[4], 0.0) for i, g in enumerate(legs) if i not in used]
    shapes = [((f, e), (KIND_CIRCLE, x, y, 2 * r)) for f, e, x, y, r in circles]
    shapes += [((f, e), (KIND_BLOB, x, y, size)) for f, e, x, y, size in blobs]
    for seg in sorted({li[0] for li in lines}):
        mine = [li for li in lines if li[0] == seg]
        pts = np.array([li[3:5] for li in mine] + [li[5:7] for li in mine])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        span = (min(li[1] for li in mine), max(li[2] for li in mine))
        shapes.append((span, (KIND_RECT, *(0.5 * (lo + hi)), float(np.hypot(*(hi - lo))))))
    shapes = [s for s in shapes if not any(overlap(s[0], g[:2]) > 0 for g in legs)]
    for span, (k, x, y, size) in shapes:
        if size <= d_max:
            rows.append((k, x, y, size, max([p for f, e, p in weak if overlap(span, (f, e)) > 0], default=0.0)))
    covers = []
    for f, e, _ in weak:
        most = max([overlap(span, (f, e)) for span, _ in shapes], default=0)
        best = next((row for span, row in shapes if overlap(span, (f, e)) == most), None) if most > 0 else None
        covers.append(None if best is None or best[3] > d_max else _key(*best))
    return sorted(_key(*r[:4]) + (round(r[4], 9),) for r in rows), covers


def _key(kind, x, y, size) -> tuple:
    return int(kind), round(float(x), 9), round(float(y), 9), round(float(size), 9)


f8, i8 = np.float64, np.int64


def test_learned_measurements_match_the_reference():
    """The compiled measurements of a scan's strong legs and weak candidates (random beams: a weak candidate may
    share beams with none, one or two segments) are the plain statement's, each weak one's cover included."""
    rng = np.random.default_rng(3)
    covered = 0
    for _ in range(60):
        n = rng.integers(0, 12)
        segs = rng.permutation(30)[:n]
        kinds = rng.integers(0, 4, n)  # 0 circle, 1 blob, 2 line(s), 3 a detected leg (sometimes also a circle)
        circles, blobs, lines, legs = [], [], [], []
        for seg, kind in zip(segs.tolist(), kinds.tolist(), strict=True):
            x, y = rng.uniform(-5, 5, 2)
            f = 10 * seg + int(rng.integers(0, 3))
            e = f + int(rng.integers(0, 6))
            if kind == 0:
                circles.append((f, e, x, y, rng.uniform(0.05, 0.5)))
            elif kind == 1:
                blobs.append((f, e, x, y, rng.uniform(0.05, 2.0)))
            elif kind == 2:
                for _ in range(rng.integers(1, 3)):
                    lines.append((seg, f, e, x, y, x + rng.uniform(-1, 1), y + rng.uniform(-1, 1)))
            else:
                if rng.random() < 0.7:
                    circles.append((f, e, x, y, 0.08))
                legs.append((f, e, x, y, rng.uniform(0.05, 0.2)))
        near = [10 * seg for seg in segs.tolist()] or [0]
        wf = np.where(rng.random(6) < 0.8, rng.choice(near, 6), rng.integers(0, 300, 6))[: rng.integers(0, 7)]
        wf = wf + rng.integers(-6, 8, len(wf))  # on a segment's beams, across two, or on none
        weak = [(int(a), int(a + rng.integers(0, 12)), float(rng.uniform(0.05, 0.8))) for a in np.maximum(wf, 0)]

        def col(rows, k, t=f8):
            return np.array([r[k] for r in rows], t).reshape(-1)

        got = _kernels.learned_measurements(
            Circles(col(circles, 0, i8), col(circles, 1, i8), col(circles, 2), col(circles, 3), col(circles, 4)),
            Blobs(
                col(blobs, 0, i8),
                col(blobs, 1, i8),
                col(blobs, 2),
                col(blobs, 3),
                col(blobs, 4),
                np.zeros(len(blobs), i8),
            ),
            Lines(
                col(lines, 0, i8),
                col(lines, 1, i8),
                col(lines, 2, i8),
                col(lines, 3),
                col(lines, 4),
                col(lines, 5),
                col(lines, 6),
            ),
            Legs(col(legs, 0, i8), col(legs, 1, i8), col(legs, 2), col(legs, 3), col(legs, 4), np.zeros(len(legs))),
            (col(weak, 0, i8), col(weak, 1, i8), col(weak, 2)),
            param_vector(stride_max=0.9, d_max=1.5),
        )
        x, y, size, kind, _, prob, cover = got
        rows = sorted(
            _key(k, a, b, s) + (round(float(p), 9),) for k, a, b, s, p in zip(kind, x, y, size, prob, strict=True)
        )
        want_rows, want_covers = reference_measurements(circles, blobs, lines, legs, weak, 0.9, 1.5)
        assert rows == want_rows
        assert [None if c < 0 else _key(kind[c], x[c], y[c], size[c]) for c in cover] == want_covers
        covered += sum(c is not None for c in want_covers)
    assert covered > 50


# ---------------------------------------------------------------------- scenes with beams and ranges
GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0)
ANGLES = GEOM.angle_min + GEOM.angle_increment * np.arange(GEOM.n_beams)
LEG_R = 0.06  # m, a leg's radius


def _beams(x: float, y: float, r: float) -> tuple[int, int]:
    """The beams (inclusive) a disc of radius r at (x, y) (sensor frame, m) covers."""
    b = (np.arctan2(y, x) - GEOM.angle_min) / GEOM.angle_increment
    h = np.arcsin(min(r / np.hypot(x, y), 1.0)) / GEOM.angle_increment
    return int(np.ceil(b - h)), int(np.floor(b + h))


def scan(legs=(), blobs=(), circles=()) -> ScanFeatures:
    """One scan's features, sensor frame, m: legs (x, y, p), each a leg candidate of width 2 LEG_R the detector
    scored p and the small circle of its beams (what a weak candidate is measured as); blobs (x, y, size) and
    circles (x, y, r) of their own beams."""
    g = np.zeros(len(legs), LEG_DTYPE)
    c = np.zeros(len(legs) + len(circles), CIRCLE_DTYPE)
    b = np.zeros(len(blobs), BLOB_DTYPE)
    for i, (x, y, p) in enumerate(legs):
        g[i]["first"], g[i]["last"] = c[i]["first"], c[i]["last"] = _beams(x, y, LEG_R)
        g[i]["x"], g[i]["y"], g[i]["width"], g[i]["probability"], g[i]["segment"] = x, y, 2 * LEG_R, p, i
        c[i]["x"], c[i]["y"], c[i]["radius"], c[i]["segment"] = x, y, LEG_R, i
    for i, (x, y, r) in enumerate(circles, len(legs)):
        c[i]["first"], c[i]["last"] = _beams(x, y, r)
        c[i]["x"], c[i]["y"], c[i]["radius"], c[i]["segment"] = x, y, r, i
    for i, (x, y, size) in enumerate(blobs):
        b[i]["first"], b[i]["last"] = _beams(x, y, size / 2)
        b[i]["x"], b[i]["y"], b[i]["size"], b[i]["segment"] = x, y, size, len(c) + i
    return ScanFeatures(np.zeros(0, LINE_DTYPE), c, b, g)


def ranges(discs=(), wall: float | None = None) -> np.ndarray:
    """A scan's ranges (float32, m): the nearest of the discs (x, y, r; sensor frame) and a wall across the way
    `wall` m ahead; +inf where a beam hits nothing within range."""
    ux, uy = np.cos(ANGLES), np.sin(ANGLES)
    r = np.full(GEOM.n_beams, np.inf)
    if wall is not None:
        ahead = ux > wall / GEOM.range_max
        r[ahead] = wall / ux[ahead]
    for x, y, rad in discs:
        t = ux * x + uy * y
        d2 = x * x + y * y - t * t
        hit = (t > 0) & (d2 <= rad * rad)
        r = np.where(hit, np.minimum(r, t - np.sqrt(np.maximum(rad * rad - d2, 0.0))), r)
    return r.astype(np.float32)


def standing(x: float, y: float, p: float, k: int) -> list[tuple[float, float, float]]:
    """The legs (x, y, p) of someone standing at (x, y), scan k (a little sway)."""
    sway = 0.01 * np.sin(0.7 * k)
    return [(x + sway, y + 0.15, p), (x - sway, y - 0.15, p)]


def tracked(out: np.ndarray, near: tuple[float, float], within: float = 0.4) -> np.ndarray:
    """The confirmed tracks of `out` within `within` m of `near` (sensor frame)."""
    d = np.hypot(out["x"] - near[0], out["y"] - near[1])
    return out[(out["status"] != 0) & (d <= within)]


def new_tracker(params: TrackingParams = P, geometry: ScanGeometry | None = GEOM) -> Tracker:
    return Tracker(params, geometry, learned=True, leg_threshold=THR)


# ------------------------------------------------------------------------------------ the life cycle
def test_a_person_is_promoted_once_and_kept_until_the_evidence_falls_below_person_maintain():
    """Strong paired legs make a person; legs the detector then scores 0.35 (weak, evidence settling below
    person_evidence but above person_maintain) keep them one; legs scored 0.1 (below person_maintain, taken as
    the circles they are) bring the evidence below person_maintain: no person any more, the same track."""
    tracker = new_tracker(geometry=None)
    phases = [(0.95, 15), (0.35, 50), (0.1, 30)]
    classes, ids, k = [], [], 0
    for p, n in phases:
        for _ in range(n):
            out = tracked(tracker.step(k * 100_000_000, scan(standing(2.0, 0.5, p, k))), (2.0, 0.5))
            assert len(out) <= 1
            classes.append(int(out["classification"][0]) if len(out) else -1)
            ids.append(int(out["id"][0]) if len(out) else -1)
            k += 1
    first = classes.index(CLASS_PERSON)
    assert first <= 5 and len(set(ids[first:])) == 1
    low = np.array(classes[15:65])
    assert (low == CLASS_PERSON).all()  # kept through 5 s of weak legs: settled at 0.35 < person_evidence
    evidence = tracker.tracks.column(state.LEG_SCORE)[0]
    assert evidence < P.person_maintain
    assert classes[-1] != CLASS_PERSON and classes[65:].count(CLASS_PERSON) < 25  # dropped, not promoted back


def test_hits_that_are_no_leg_candidate_leave_the_evidence_as_it_is():
    """A person whose legs the detector stops finding (their segment a blob it gave no probability) keeps the
    evidence and the label: hits that are no leg candidate are neutral."""
    tracker = new_tracker(geometry=None)
    for k in range(15):
        tracker.step(k * 100_000_000, scan(standing(2.0, 0.5, 0.95, k)))
    before = tracker.tracks.column(state.LEG_SCORE).copy()
    hits = tracker.tracks.column(state.LEG_HITS).copy()
    assert before[0] >= P.person_evidence
    for k in range(15, 75):
        out = tracked(tracker.step(k * 100_000_000, scan(blobs=[(2.0, 0.5, 0.3)])), (2.0, 0.5))
        assert len(out) == 1 and out["classification"][0] == CLASS_PERSON and out["status"][0] != STATUS_COASTING
    np.testing.assert_array_equal(tracker.tracks.column(state.LEG_SCORE), before)
    np.testing.assert_array_equal(tracker.tracks.column(state.LEG_HITS), hits)
    assert tracker.tracks.votes[0, KIND_BLOB] == 60


def test_a_person_coasts_person_coast_seconds_flagged_occluded_while_a_non_person_dies_after_delete_after():
    tracker = new_tracker(geometry=None)  # no ranges: nothing unseen counts as hidden
    for k in range(15):
        tracker.step(k * 100_000_000, scan(standing(2.0, 0.5, 0.95, k), circles=[(3.0, -1.5, 0.3)]))
    out = tracker.output()
    person = out[out["classification"] == CLASS_PERSON]
    other = out[out["classification"] == CLASS_CIRCLE_OBJECT]
    assert len(person) == 1 and len(other) == 1 and (out["status"] != 0).all()
    seen = {}
    for k in range(15, 60):  # both leave the scanner's sight at 1.4 s
        out = tracker.step(k * 100_000_000, scan())
        for r in out:
            seen.setdefault(int(r["id"]), []).append((round(0.1 * (k - 14), 1), int(r["occluded"]), int(r["status"])))
    gone = {i: v[-1][0] for i, v in seen.items()}
    assert P.delete_after <= gone[int(other["id"][0])] <= P.delete_after + 0.1
    assert P.person_coast <= gone[int(person["id"][0])] <= P.person_coast + 0.1
    coast = seen[int(person["id"][0])]
    assert all(occluded == 1 and status == STATUS_COASTING for _, occluded, status in coast)
    assert all(occluded == 0 for _, occluded, _ in seen[int(other["id"][0])])


def test_a_person_standing_longer_than_background_time_stays_a_person_off_the_background():
    """Someone standing 8 s (background_time is 3 s) in front of a wall: a person all along, and the places of
    their legs never become background (their returns feed no cell), while the wall behind does."""
    tracker = new_tracker()
    legs = [(2.0, 0.5 + d) for d in (0.15, -0.15)]
    classes = []
    for k in range(80):
        out = tracker.step(
            k * 100_000_000, scan([(x, y, 0.95) for x, y in legs]), ranges([(x, y, LEG_R) for x, y in legs], wall=5.0)
        )
        classes.append(tracked(out, (2.0, 0.5))["classification"].tolist())
    assert all(c == [CLASS_PERSON] for c in classes[5:])
    score, _, _, _ = tracker._bg
    n = int(np.sqrt(len(score)) + 0.5)
    ctx = tracker._ctx
    prm = P.kernel_vector(THR)
    places = np.array([[x - LEG_R, y] for x, y in legs] + [[5.0, 0.5]])  # the legs' fronts, the wall behind
    on = _kernels.on_background(
        score,
        places[:, 0].copy(),
        places[:, 1].copy(),
        np.zeros(3),
        0.0,
        0.0,
        ctx[state.C_BG_X0],
        ctx[state.C_BG_Y0],
        n,
        prm,
    )
    np.testing.assert_array_equal(on, [False, False, True])


# ------------------------------------------------------------------------ carried beams (a moving robot)
def _driving(swinging: bool, n: int = 45) -> list[list[int]]:
    """A robot driving at 1 m/s (10 Hz, poses given) towards a wall, with a pair of leg-like things ahead the
    detector scores 0.95: `swinging`, a person walking 1.5 m ahead at the robot's speed (still in the sensor
    frame, legs swinging); else a part of the robot 0.5 m away (legs fixed in the sensor frame). Returns the
    classes of the confirmed tracks per scan."""
    tracker = new_tracker()
    part = [(0.5 * np.cos(-1.1), 0.5 * np.sin(-1.1) + d) for d in (0.12, -0.12)]
    classes = []
    for k in range(n):
        t = 0.1 * k
        pose = np.array([t, 0.0, 0.0])
        if swinging:
            legs = [(float(q[0] - t), float(q[1])) for q in walker_legs(t, (1.5, 0.0), (1.0, 0.0))]
        else:
            legs = part
        out = tracker.step(
            k * 100_000_000,
            scan([(x, y, 0.95) for x, y in legs]),
            ranges([(x, y, LEG_R) for x, y in legs], wall=7.5 - t),
            pose,
        )
        classes.append(out[out["status"] != 0]["classification"].tolist())
    return classes


def test_a_part_of_the_robot_on_beams_that_keep_their_range_while_it_drives_is_no_leg():
    """The robot's own part, like legs to the detector: a person while the robot has not driven carried_travel
    (nothing tells it from someone standing there), then its beams are carried and the candidates on them are no
    legs however sure the detector is: no person any more, tracked all the same."""
    classes = _driving(swinging=False)
    assert CLASS_PERSON in classes[5]
    after = classes[int(10 * (P.carried_travel + 0.3)) :]
    assert not any(CLASS_PERSON in c for c in after) and all(len(c) >= 1 for c in after)


def test_a_person_walking_in_front_of_a_moving_scanner_is_a_person():
    """The same drive with a person walking ahead (the followed person): still in the sensor frame, but their
    swinging legs move their beams' ranges, so no beam of theirs is carried: a person all along."""
    classes = _driving(swinging=True)
    assert all(c == [CLASS_PERSON] for c in classes[3:])


# ---------------------------------------------------------------------------------- weak candidates
def test_a_person_track_takes_weak_legs_above_person_maintain_and_not_below():
    """A person's legs scored 0.5 (weak: below the threshold, above person_maintain) are taken by the person
    track as its pair; scored 0.1 (below person_maintain) they are not: the track takes them as the circles
    they are measured as, and the pair count stops."""
    tracker = new_tracker(geometry=None)
    counts = []
    for k, p in enumerate([0.95] * 15 + [0.5] * 10 + [0.1] * 10):
        out = tracked(tracker.step(k * 100_000_000, scan(standing(2.0, 0.5, p, k))), (2.0, 0.5))
        assert k < 2 or (len(out) == 1 and int(out["id"][0]) == 1)
        counts.append(tracker.tracks.votes[0].copy())
    pairs = [int(v[KIND_PERSON]) for v in counts]
    assert pairs[24] - pairs[14] == 10  # each weak pair above person_maintain taken as a pair
    assert pairs[34] == pairs[24]  # none below it
    assert counts[34][KIND_CIRCLE] - counts[24][KIND_CIRCLE] == 10
    assert counts[24][KIND_CIRCLE] == counts[14][KIND_CIRCLE] == 0


# --------------------------------------------------------------------------------- datmo track, config
N_CLI = 30
STAMPS = 1_700_000_000_000_000_000 + np.arange(N_CLI, dtype=np.int64) * 100_000_000


def _features_log(path, threshold: float) -> list[ScanFeatures]:
    """A log of scans and /datmo/features made by the shipped detector (say its provenance), whose threshold
    it records as `threshold`: someone standing whose legs it scored 0.6."""
    run = ScanRun(STAMPS, np.full((N_CLI, GEOM.n_beams), 7.5, np.float32), GEOM)
    feats = [scan(standing(2.0, 0.5, 0.6, k)) for k in range(N_CLI)]
    payloads = [
        cdr.encode(
            types.FEATURES,
            {
                "stamp_ns": int(s),
                "frame_id": "laser",
                "lines": f.lines,
                "circles": f.circles,
                "blobs": f.blobs,
                "legs": f.legs,
            },
        )
        for s, f in zip(STAMPS, feats, strict=True)
    ]
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
        w.write_many(mcapio.TOPIC_FEATURES, types.FEATURES, STAMPS, payloads)
        w.add_metadata(
            "datmo.params",
            {
                "features": json.dumps({"leg_model": "default"}),
                "leg_model": json.dumps({"model": "default", "threshold": threshold}),
            },
        )
    return feats


@pytest.mark.parametrize("threshold", [0.5, 0.9])
def test_track_takes_the_leg_threshold_its_features_log_records(tmp_path, threshold):
    """Legs scored 0.6 are legs under a recorded threshold of 0.5 and weak under 0.9 (measured as their circles,
    so the tracks differ): `datmo track` gives what tracking with that threshold gives, and records it."""
    from datmo_cli.passes.stages import track_run

    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    feats = _features_log(src, threshold)
    result = CliRunner().invoke(cli, ["track", str(src), "-o", str(out), "--covariance", "--hindsight-lag", "0"])
    assert result.exit_code == 0, result.output
    _, payloads = mcapio.read_messages(out, mcapio.TOPIC_TRACKS)
    got = [cdr.decode(types.TRACKS, p)["tracks"] for p in payloads]
    want = track_run(
        mcapio.run_from_log(mcapio.read_log(src, topics=None)), feats, learned=True, leg_threshold=threshold
    )
    assert [g.tobytes() for g in got] == [w.tobytes() for w in want.tracks]
    other = track_run(
        mcapio.run_from_log(mcapio.read_log(src, topics=None)), feats, learned=True, leg_threshold=1.4 - threshold
    )
    assert [g.tobytes() for g in got] != [w.tobytes() for w in other.tracks]
    if threshold == 0.5:
        assert (got[-1]["classification"] == CLASS_PERSON).sum() == 1
    recorded = json.loads(mcapio.summary(out).metadata["datmo.params"]["leg_model"])
    assert recorded["threshold"] == threshold


@pytest.mark.parametrize(
    ("table", "key"),
    [
        ("track", "leg_probability"),
        ("track", "moving_person_evidence"),
        ("track", "moving_person_pairs"),
        ("features", "leg_min_probability"),
    ],
)
def test_removed_keys_are_refused_in_one_line_naming_the_key(tmp_path, table, key):
    cfg = tmp_path / "old.toml"
    cfg.write_text(f"[{table}]\n{key} = 0.5\n")
    result = CliRunner().invoke(cli, ["config", "--config", str(cfg)])
    assert result.exit_code != 0
    assert result.stderr.startswith(f"datmo: error: {cfg}: {table}.{key}: no longer a parameter: ")
    assert result.stderr.count("\n") == 1


# ------------------------------------------------------------------------ people without the walking rule
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
    scans = [
        {"legs": [(2.0 + rng.normal(0, 0.01), 0.15, 0.12), (2.0 + rng.normal(0, 0.01), -0.15, 0.12)]} for _ in range(30)
    ]
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


def test_a_walking_person_is_a_dynamic_person():
    scans = [
        {"legs": [(float(p[0]), float(p[1]), 0.12) for p in walker_legs(0.1 * k, (1.0, -3.0), (0.3, 1.0))]}
        for k in range(60)
    ]
    out = _final(_run(scans, learned=True))
    people = out[out["classification"] == CLASS_PERSON]
    assert len(people) == 1 and people["mobility"][0] == MOBILITY_DYNAMIC


def test_small_circles_the_detector_rejects_are_not_people():
    scans = [{"circles": [(2.0, 1.0, 0.06), (2.3, 1.0, 0.06)]} for _ in range(30)]
    out = _final(_run(scans, learned=True))
    assert len(out) >= 1
    assert not (out["classification"] == CLASS_PERSON).any()
    assert (out["classification"] == CLASS_CIRCLE_OBJECT).all()
