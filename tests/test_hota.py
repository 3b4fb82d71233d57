"""HOTA, DetA, AssA and LocA of `datmo evaluate` (TrackEval's HOTA metric) on cases computed by hand.

HOTA (Luiten et al. 2021): at a threshold alpha, a target and a hypothesis matched in a frame with similarity
S >= alpha are a true positive (TP); unmatched targets are FN, unmatched hypotheses FP.
DetA = |TP| / (|TP| + |FN| + |FP|); for a TP c pairing target g with hypothesis h,
A(c) = |TPA| / (|TPA| + |FNA| + |FPA|), with TPA the TPs pairing g with h, FNA g's other detections,
FPA h's other detections; AssA = mean of A(c) over the TPs; HOTA = sqrt(DetA x AssA); the figures reported
are the means over alpha = 0.05, 0.10, ..., 0.95. datmo's similarity is S = max(0, 1 - d / match_radius).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from datmo_cli import evaluate as ev

pytestmark = pytest.mark.unit

FAR = 5.0  # m between the two targets: never a doubt which hypothesis is near which


def frames(rows: list[list[tuple[int, float, float]]], cls: int = 1) -> ev.Frames:
    """Frames with stamps 0, 1, ...; rows[k] = frame k's (id, x, y)."""
    flat = [r for frame in rows for r in frame]
    offsets = np.concatenate([[0], np.cumsum([len(f) for f in rows])]).astype(np.int64)
    return ev.Frames(
        np.arange(len(rows), dtype=np.int64),
        offsets,
        np.array([r[0] for r in flat], np.int64),
        np.array([r[1] for r in flat], float),
        np.array([r[2] for r in flat], float),
        np.full(len(flat), cls, np.int64),
    )


def scores(gt_rows, hyp_rows, radius: float = 0.5) -> dict:
    return ev.evaluate(frames(gt_rows), frames(hyp_rows), match_radius=radius)["all"]


def assert_figures(s: dict, expected: dict) -> None:
    for key, value in expected.items():
        if value is None:
            assert s[key] is None, key
        else:
            assert s[key] == pytest.approx(value, abs=1e-9), key


# Two targets, A (id 1) at the origin and B (id 2) 5 m away, in four frames. Hypotheses sit exactly on them
# (d = 0, S = 1, so every alpha gives the same figures): track 10 follows A in frames 0-1, track 11 takes A
# over in frames 2-3 (an identity switch), track 20 follows B in frames 0-2 and B is missed in frame 3.
SWITCH_AND_MISS_GT = [[(1, 0.0, 0.0), (2, FAR, 0.0)]] * 4
SWITCH_AND_MISS_HYPS = [
    [(10, 0.0, 0.0), (20, FAR, 0.0)],
    [(10, 0.0, 0.0), (20, FAR, 0.0)],
    [(11, 0.0, 0.0), (20, FAR, 0.0)],
    [(11, 0.0, 0.0)],
]


def test_an_identity_switch_and_a_miss():
    # TP = 7 (A: 4, B: 3), FN = 1 (B in frame 3), FP = 0: DetA = 7 / 8.
    # (A, 10): TPA 2, FNA 4 - 2 = 2, FPA 0 -> A = 2/4, for its 2 TPs; (A, 11) likewise 2/4 for 2 TPs;
    # (B, 20): TPA 3, FNA 4 - 3 = 1, FPA 0 -> A = 3/4, for its 3 TPs.
    # AssA = (2 * 1/2 + 2 * 1/2 + 3 * 3/4) / 7 = 4.25 / 7 = 17/28; HOTA = sqrt(7/8 * 17/28) = sqrt(17/32).
    # LocA: every match at S = 1.
    s = scores(SWITCH_AND_MISS_GT, SWITCH_AND_MISS_HYPS)
    assert_figures(s, {"deta": 7 / 8, "assa": 17 / 28, "hota": math.sqrt(17 / 32), "loca": 1.0})
    # CLEAR-MOT on the same case, for comparison: one switch, one miss
    assert (s["num_switches"], s["num_misses"], s["num_false_positives"]) == (1, 1, 0)


def test_localisation_error_counts_only_at_lower_thresholds():
    # One target, two frames, radius 1 m; track 5 on it in frame 0 (S = 1) and 0.275 m off in frame 1
    # (S = 0.725). For the 14 thresholds alpha <= 0.70: TP 2, DetA = AssA = HOTA = 1, LocA = (1 + 0.725) / 2.
    # For the 5 thresholds alpha >= 0.75 frame 1 is a FN and a FP: TP 1, DetA = 1 / 3;
    # A = 1 / (2 + 2 - 1) = 1/3, so AssA = 1/3, HOTA = 1/3; LocA = 1.
    # Means: DetA = AssA = HOTA = (14 + 5/3) / 19 = 47/57; LocA = (14 * 0.8625 + 5) / 19 = 17.075 / 19.
    s = scores([[(1, 0.0, 0.0)], [(1, 0.0, 0.0)]], [[(5, 0.0, 0.0)], [(5, 0.275, 0.0)]], radius=1.0)
    assert_figures(s, {"hota": 47 / 57, "deta": 47 / 57, "assa": 47 / 57, "loca": 17.075 / 19})


def test_perfect_tracks_score_one():
    hyps = [[(i + 100, x, y) for i, x, y in f] for f in SWITCH_AND_MISS_GT]
    assert_figures(scores(SWITCH_AND_MISS_GT, hyps), {"hota": 1.0, "deta": 1.0, "assa": 1.0, "loca": 1.0})


def test_empty_cases():
    nothing = [[], []]
    assert_figures(scores(nothing, nothing), {"hota": None, "deta": None, "assa": None, "loca": None})
    # targets and no tracks, or tracks and no targets: nothing detected, HOTA 0
    one = [[(1, 0.0, 0.0)], [(1, 0.0, 0.0)]]
    assert_figures(scores(one, nothing), {"hota": 0.0, "deta": 0.0, "assa": 0.0, "loca": None})
    assert_figures(scores(nothing, one), {"hota": 0.0, "deta": 0.0, "assa": 0.0, "loca": None})


def test_no_match_beyond_the_match_radius():
    # 0.5 m off at a 0.5 m radius: S = 0, below every alpha (CLEAR-MOT still matches at exactly the radius)
    s = scores([[(1, 0.0, 0.0)]], [[(7, 0.5, 0.0)]])
    assert_figures(s, {"hota": 0.0, "deta": 0.0, "assa": 0.0, "loca": None})
    s = scores([[(1, 0.0, 0.0)]], [[(7, 0.24, 0.0)]])  # S = 0.52: a TP at alpha 0.05..0.50, 10 of 19
    assert_figures(s, {"deta": 10 / 19, "hota": 10 / 19, "loca": (10 * 0.52 + 9) / 19})


def test_per_class_figures():
    gt = frames([[(1, 0.0, 0.0)], [(1, 0.0, 0.0)]])
    gt.cls[:] = 1
    hyps = frames([[(5, 0.0, 0.0), (6, FAR, 0.0)], [(5, 0.0, 0.0), (6, FAR, 0.0)]])
    hyps.cls[:] = [1, 3, 1, 3]  # a person on the target, a false rectangular object elsewhere
    s = ev.evaluate(gt, hyps)
    # all: TP 2, FP 2 -> DetA 1/2, AssA 1, HOTA sqrt(1/2); person: perfect; rectangular object: only FPs
    assert_figures(s["all"], {"deta": 0.5, "assa": 1.0, "hota": math.sqrt(0.5)})
    assert_figures(s["person"], {"hota": 1.0})
    assert_figures(s["rectangular object"], {"hota": 0.0, "loca": None})


def test_similarity_is_one_minus_distance_over_radius():
    hf = ev.HotaFrames()
    hf.add(np.array([1]), np.array([2, 3]), np.array([[0.1, 0.7]]), 0.5)
    hf.add(np.array([], np.int64), np.array([], np.int64), np.zeros((0, 0)), 0.5)  # empty: left out
    assert len(hf.similarity) == 1 and hf.similarity[0] == pytest.approx(np.array([[0.8, 0.0]]))
