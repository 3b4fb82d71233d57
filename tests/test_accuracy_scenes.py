"""benchmarks/accuracy_scenes.py (make accuracy): each figure on a hand-made run whose answer is known, and the
whole chain (simulate, run as datmo run does, load, score; the ROS 1 bag compared) on a short lab-drive run."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import accuracy_scenes as A
from datmo_cli.logs import cdr, types
from datmo_cli.logs.vocabulary import (
    CLASS_PERSON,
    CLASS_UNKNOWN,
    CLASS_WALL,
    MOBILITY_DYNAMIC,
    MOBILITY_STATIC,
    STATUS_CONFIRMED,
    STATUS_TENTATIVE,
)

pytestmark = pytest.mark.unit

GT = cdr.element_dtype(types.GROUND_TRUTH_OBJECT)
TRACK = cdr.element_dtype(types.TRACK)


def objects(rows):
    """GroundTruthObject elements of (id, class, x, y, visible, moving)."""
    out = np.zeros(len(rows), GT)
    for i, (oid, cls, x, y, visible, moving) in enumerate(rows):
        out[i]["id"], out[i]["classification"], out[i]["x"], out[i]["y"] = oid, cls, x, y
        out[i]["visible"], out[i]["moving"], out[i]["length"], out[i]["width"] = visible, moving, 0.3, 0.3
    return out


def tracks(rows):
    """Track elements of (id, x, y, class, mobility, status)."""
    out = np.zeros(len(rows), TRACK)
    for i, (tid, x, y, cls, mob, status) in enumerate(rows):
        out[i]["id"], out[i]["x"], out[i]["y"], out[i]["classification"] = tid, x, y, cls
        out[i]["mobility"], out[i]["status"] = mob, status
    return out


def scene_run(gt_frames, tr_frames, period=0.1):
    gt = np.concatenate([objects(f) for f in gt_frames])
    tr = np.concatenate([tracks(f) for f in tr_frames])
    off = lambda frames: np.concatenate([[0], np.cumsum([len(f) for f in frames])]).astype(np.int64)  # noqa: E731
    return A.SceneRun(off(gt_frames), gt, off(tr_frames), tr, period)


P, D, S, C, T = CLASS_PERSON, MOBILITY_DYNAMIC, MOBILITY_STATIC, STATUS_CONFIRMED, STATUS_TENTATIVE
WALL = (9, CLASS_WALL, 3.0, 0.0, 1, 0)


@pytest.fixture
def hand_made():
    """Four scans: a walker (id 1) and a standing person (id 2), both in view but the walker hidden in scan 3; a
    wall. The walker's track (7) is a person in scans 0 and 1, unknown in scan 2, and leaves for a tentative one
    in scan 3; the standing person's track (8) is a static person in scans 0-2 and a dynamic one in scan 3; track
    9 sits on the wall, dynamic in scans 1-3; track 10 is a person 0.7 m from the walker (too far to match)."""
    gt, tr = [], []
    for k in range(4):
        gt.append([(1, P, 1.0 + 0.1 * k, 0.5, 0 if k == 3 else 1, 1), (2, P, 2.0, -1.0, 1, 0), WALL])
        rows = [
            (7, 1.0 + 0.1 * k, 0.55, P if k < 2 else CLASS_UNKNOWN, D, C if k < 3 else T),
            (8, 2.05, -1.0, P, S if k < 3 else D, C),
        ]
        if k:
            rows.append((9, 3.0, 0.1, CLASS_UNKNOWN, D, C))
        if k == 0:
            rows.append((10, 1.0, 1.2, P, D, C))
        tr.append(rows)
    return scene_run(gt, tr)


def test_matching_is_one_to_one_within_half_a_metre(hand_made):
    m = A.match(hand_made, lambda g: g["classification"] == CLASS_PERSON)
    walker = np.flatnonzero(hand_made.gt["id"] == 1)
    assert hand_made.tracks["id"][m[walker[:3]]].tolist() == [7, 7, 7] and m[walker[3]] == -1  # hidden: no match
    assert (m[hand_made.gt["id"] == 9] == -1).all()  # not a target


def test_person_share_counts_the_frames_in_view(hand_made):
    assert A.person_share(hand_made, [1]) == pytest.approx(2 / 3)  # person, person, unknown; scan 3 not in view
    assert A.person_share(hand_made, [2]) == 1.0
    assert A.person_share(hand_made, [5]) is None


def test_standing_and_walking_shares(hand_made):
    assert A.standing_static_person_share(hand_made) == pytest.approx(3 / 4)  # dynamic in scan 3
    assert A.walking_dynamic_share(hand_made) == 1.0


def test_longest_dynamic_on_a_static_thing(hand_made):
    worst = A.longest_dynamic_on_static(hand_made)
    # the wall's track: 3 consecutive scans (0.3 s)
    assert worst == {"seconds": pytest.approx(0.3), "track": 9, "at_s": pytest.approx(0.1), "on": "wall 9 at 0.00 m"}
    # a person standing is no static piece (standing_static_person_share scores it): a dynamic track on one counts
    # only when nothing else is there
    run = scene_run([[(2, P, 2.0, -1.0, 1, 0)]] * 5, [[(8, 2.0, -1.0, P, D, C)]] * 5, period=0.5)
    assert A.longest_dynamic_on_static(run)["seconds"] == 0.0
    run = scene_run([[(2, P, 2.0, -1.0, 1, 0)]] * 5, [[(8, 4.0, -1.0, P, D, C)]] * 5, period=0.5)
    assert A.longest_dynamic_on_static(run)["seconds"] == 2.5


def test_people_mota_and_switches(hand_made):
    m = A.people_mota(hand_made)
    # 7 person frames in view; misses: the walker in scan 2 (its track is unknown); false positives: track 10 in
    # scan 0 (0.7 m from the walker, away from the wall's don't-care region); no switch
    assert m["mota"] == pytest.approx(1 - 2 / 7) and m["switches"] == 0
    assert m["person_minutes"] == pytest.approx(7 * 0.1 / 60)
    swap = scene_run(
        [[(1, P, 1.0, 0.0, 1, 1)]] * 4, [[(7, 1.0, 0.0, P, D, C)]] * 2 + [[(8, 1.0, 0.0, P, D, C)]] * 2, period=15.0
    )
    m = A.people_mota(swap)
    assert m["switches"] == 1 and m["switches_per_person_minute"] == pytest.approx(1.0)


def test_a_short_lab_drive_runs_end_to_end_and_its_bag_gives_the_same_tracks(tmp_path):
    figures = A.lab_drive_figures(tmp_path, duration=4.0)
    assert figures["_scans"] == 40 and figures["ROS 1 bag gives the same tracks"] == (True, 40, 40)
    for name in ("standing people static and person", "walking people dynamic"):
        assert figures[name] is None or 0.0 <= figures[name] <= 1.0
    assert figures["longest dynamic on a static thing s"]["seconds"] >= 0.0
    assert A._verdict("people MOTA", 0.95) == "meets" and A._verdict("people MOTA", 0.5) == "MISSES"
    assert A._verdict("ROS 1 bag gives the same tracks", False) == "MISSES"
