"""Accuracy of tracking against ground truth, as pure functions on arrays (used by `make accuracy` and tests).

MOTA and IDF1 come from datmo_cli.evaluate (py-motmetrics); here are the figures it does not give: how often
a confirmed track's class is right, identity switches of one object, the share of labelled legs a tracker
covers, and the ideal features of a simulated scan (what a perfect perception would give the tracker).
Positions in the sensor frame, metres.
"""

from __future__ import annotations

import numpy as np

from benchmarks.synthetic_features import features_from_lists
from datmo_cli.logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_COLUMN,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    STATUS_CONFIRMED,
)
from datmo_cli.tracking.measurements import ScanFeatures


def ideal_features(
    offsets: np.ndarray, objects: np.ndarray, rng: np.random.Generator, noise: float = 0.01, degraded: bool = False
) -> list[ScanFeatures]:
    """Per scan, the features a perfect perception would give for the visible ground-truth objects:
    two leg circles (radius 0.1 m) per person, a circle per circle object or column, a line across each
    rectangular object; positions with Gaussian noise of `noise` m. `degraded` makes it harder, like a
    real perception: a leg hidden behind the other one (same bearing within a leg's width), legs closer
    than 0.25 m seen as one blob, and 5 % of the features missed."""
    scans = []
    for k in range(len(offsets) - 1):
        circles, lines, blobs = [], [], []
        for g in objects[offsets[k] : offsets[k + 1]]:
            if not g["visible"]:
                continue
            c = int(g["classification"])
            if c == CLASS_PERSON:
                legs = [
                    (float(g["left_leg_x"]), float(g["left_leg_y"])),
                    (float(g["right_leg_x"]), float(g["right_leg_y"])),
                ]
                if degraded:
                    (ax, ay), (bx, by) = legs
                    if np.hypot(ax - bx, ay - by) < 0.25:
                        blobs.append(((ax + bx) / 2 + rng.normal(0, noise), (ay + by) / 2 + rng.normal(0, noise), 0.3))
                        continue
                    ra, rb = np.hypot(ax, ay), np.hypot(bx, by)
                    gap = abs(np.arctan2(ay, ax) - np.arctan2(by, bx)) * min(ra, rb)
                    if gap < 0.15:  # the farther leg is behind the nearer one
                        legs = [legs[0] if ra < rb else legs[1]]
                    legs = [leg for leg in legs if rng.random() > 0.05]
                for lx, ly in legs:
                    circles.append((lx + rng.normal(0, noise), ly + rng.normal(0, noise), 0.1))
            elif c in (CLASS_CIRCLE_OBJECT, CLASS_COLUMN):
                circles.append((g["x"] + rng.normal(0, noise), g["y"] + rng.normal(0, noise), g["length"] / 2))
            elif c == CLASS_RECTANGULAR_OBJECT:
                lines.append((g["x"] - g["width"] / 2, g["y"], g["x"] + g["width"] / 2, g["y"]))
        scans.append({"circles": circles, "lines": lines, "blobs": blobs})
    return features_from_lists(scans)


def matched_targets(
    gt_offsets: np.ndarray, gt: np.ndarray, tr_offsets: np.ndarray, tracks: np.ndarray, radius: float = 0.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Confirmed track states matched one to one, frame by frame (frames aligned one to one with the
    ground truth), to the visible targets (movers that move at some time in the run) within `radius` m.
    Returns (track id, track class, target id or -1 when unmatched, target class or 0), time ordered."""
    from scipy.optimize import linear_sum_assignment

    movers = np.isin(gt["classification"], [CLASS_PERSON, CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT])
    moved = np.unique(gt["id"][movers & (gt["moving"] == 1)])
    tid, tcls, gid, gcls = [], [], [], []
    for k in range(len(gt_offsets) - 1):
        g = gt[gt_offsets[k] : gt_offsets[k + 1]]
        g = g[(g["visible"] == 1) & np.isin(g["id"], moved)]
        t = tracks[tr_offsets[k] : tr_offsets[k + 1]]
        t = t[t["status"] == STATUS_CONFIRMED]
        if not len(t):
            continue
        ids, cls = np.full(len(t), -1, np.int64), np.zeros(len(t), np.int64)
        if len(g):
            d = np.hypot(t["x"][:, None] - g["x"][None, :], t["y"][:, None] - g["y"][None, :])
            r, c = linear_sum_assignment(np.where(d <= radius, d, 1e9))
            ok = d[r, c] <= radius
            ids[r[ok]], cls[r[ok]] = g["id"][c[ok]], g["classification"][c[ok]]
        tid.append(t["id"].astype(np.int64))
        tcls.append(t["classification"].astype(np.int64))
        gid.append(ids)
        gcls.append(cls)
    if not tid:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty, empty
    return np.concatenate(tid), np.concatenate(tcls), np.concatenate(gid), np.concatenate(gcls)


def class_accuracy(track_cls: np.ndarray, target_cls: np.ndarray, target_id: np.ndarray) -> float | None:
    """Share of confirmed track states on a target whose class equals the target's (None: no such state)."""
    on = target_id >= 0
    return float(np.mean(track_cls[on] == target_cls[on])) if on.any() else None


def id_switches(track_id: np.ndarray, target_id: np.ndarray, target: int) -> int:
    """How many times the track on `target` changes id (states in time order)."""
    ids = track_id[target_id == target]
    return int(np.sum(ids[1:] != ids[:-1])) if len(ids) else 0


def leg_coverage(
    legs: list[np.ndarray],
    circles: list[np.ndarray],
    tracks: list[np.ndarray],
    leg_radius_max: float = 0.2,
    person_radius: float = 0.5,
) -> tuple[int, int]:
    """(labelled legs covered, labelled legs) over scans: a leg (x, y) is covered when it lies inside a
    detected leg circle (radius up to leg_radius_max, plus 5 cm) or within person_radius of a person
    track (class 1). `legs[k]` (n, 2), `circles[k]` Circle elements, `tracks[k]` Track elements."""
    hit = total = 0
    for lg, c, t in zip(legs, circles, tracks, strict=True):
        if not len(lg):
            continue
        total += len(lg)
        ok = np.zeros(len(lg), bool)
        c = c[c["radius"] <= leg_radius_max]
        if len(c):
            d = np.hypot(lg[:, 0:1] - c["x"][None, :], lg[:, 1:2] - c["y"][None, :])
            ok |= (d <= c["radius"][None, :] + 0.05).any(axis=1)
        p = t[t["classification"] == CLASS_PERSON]
        if len(p):
            d = np.hypot(lg[:, 0:1] - p["x"][None, :], lg[:, 1:2] - p["y"][None, :])
            ok |= (d <= person_radius).any(axis=1)
        hit += int(ok.sum())
    return hit, total
