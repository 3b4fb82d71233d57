"""Scoring hypotheses against targets (see the package docstring): CLEAR-MOT (MOTA, MOTP) and IDF1 with
py-motmetrics, HOTA (DetA, AssA, LocA) with TrackEval, over frames aligned by stamp, with the hypotheses in
don't-care regions left out. Distances in metres, sensor frame."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..base.extras import require
from .frames import MOVER_CLASSES, Frames, Regions

METRICS = [
    "num_frames",
    "num_objects",
    "num_unique_objects",
    "num_predictions",
    "num_matches",
    "num_false_positives",
    "num_misses",
    "num_switches",
    "num_fragmentations",
    "mota",
    "motp",
    "idf1",
    "idp",
    "idr",
    "precision",
    "recall",
    "mostly_tracked",
    "partially_tracked",
    "mostly_lost",
]
HOTA_METRICS = ["hota", "deta", "assa", "loca"]
# Figures whose fall means a worse tracker (the rest: a rise is worse); used by the regression check.
HIGHER_IS_BETTER = {"mota", "idf1", "idp", "idr", "precision", "recall", "mostly_tracked", "num_matches", *HOTA_METRICS}
PROGRESS_EVERY = 500  # frames between progress calls


def require_scoring(for_: str = "scoring tracks (datmo evaluate)") -> None:
    """Import what scoring needs (the eval extra: motmetrics, TrackEval, scipy), or MissingExtraError naming it."""
    require("scipy.optimize", for_=for_)  # first: the other two import it
    require("motmetrics", for_=for_)
    require("trackeval.metrics.hota", for_=for_)


def align(gt: Frames, hyps: Frames, tolerance_ns: int = 0) -> np.ndarray:
    """For each ground-truth frame, the index of the hypothesis frame with the nearest stamp within
    `tolerance_ns`, or -1 when there is none."""
    if not len(hyps.stamps):
        return np.full(len(gt.stamps), -1, np.int64)
    order = np.argsort(hyps.stamps, kind="stable")
    hs = hyps.stamps[order]
    pos = np.clip(np.searchsorted(hs, gt.stamps), 1, max(len(hs) - 1, 1))
    left = np.clip(pos - 1, 0, len(hs) - 1)
    right = np.clip(pos, 0, len(hs) - 1)
    pick = np.where(np.abs(hs[left] - gt.stamps) <= np.abs(hs[right] - gt.stamps), left, right)
    ok = np.abs(hs[pick] - gt.stamps) <= tolerance_ns
    return np.where(ok, order[pick], -1)


def aligned_hypotheses(
    gt: Frames, hyps: Frames, *, regions: Regions | None = None, match_radius: float = 0.5, stamp_tolerance_ns: int = 0
) -> tuple[Frames, int]:
    """The hypotheses as one frame per ground-truth frame (empty where no Tracks message has its stamp),
    without those in don't-care regions that the frame's optimal assignment leaves unmatched; and how
    many were ignored."""
    from scipy.optimize import linear_sum_assignment

    match = align(gt, hyps, stamp_tolerance_ns)
    rows, counts, ignored = [], np.zeros(len(gt.stamps), np.int64), 0
    for k, j in enumerate(match.tolist()):
        if j < 0:
            continue
        idx = np.arange(hyps.offsets[j], hyps.offsets[j + 1])
        if regions is not None and len(idx):
            g = slice(gt.offsets[k], gt.offsets[k + 1])
            hx, hy = hyps.x[idx], hyps.y[idx]
            drop = regions.near(k, hx, hy, match_radius)
            if drop.any() and gt.offsets[k + 1] > gt.offsets[k]:
                # a hypothesis that the frame's best assignment gives a target is kept even in a region
                d = np.hypot(hx[:, None] - gt.x[g][None, :], hy[:, None] - gt.y[g][None, :])
                cost = np.where(d <= match_radius, d, 1e9)
                r, c = linear_sum_assignment(cost)
                drop[r[cost[r, c] < 1e9]] = False
            ignored += int(drop.sum())
            idx = idx[~drop]
        rows.append(idx)
        counts[k] = len(idx)
    idx = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return Frames(gt.stamps, offsets, hyps.ids[idx], hyps.x[idx], hyps.y[idx], hyps.cls[idx]), ignored


def _pairs(gt: Frames, hyps: Frames, k: int, cls: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame k's target ids, hypothesis ids and their distances (targets x hypotheses, metres), of class
    `cls` only unless None; hyps aligned one to one with gt (from aligned_hypotheses)."""
    g = slice(gt.offsets[k], gt.offsets[k + 1])
    h = slice(hyps.offsets[k], hyps.offsets[k + 1])
    gsel = slice(None) if cls is None else gt.cls[g] == cls
    hsel = slice(None) if cls is None else hyps.cls[h] == cls
    gx, gy = gt.x[g][gsel], gt.y[g][gsel]
    hx, hy = hyps.x[h][hsel], hyps.y[h][hsel]
    d = np.hypot(gx[:, None] - hx[None, :], gy[:, None] - hy[None, :])
    return gt.ids[g][gsel], hyps.ids[h][hsel], d


@dataclass
class HotaFrames:
    """Per frame target ids, hypothesis ids and similarities, gathered for HOTA."""

    gt_ids: list[np.ndarray] = field(default_factory=list)
    hyp_ids: list[np.ndarray] = field(default_factory=list)
    similarity: list[np.ndarray] = field(default_factory=list)  # targets x hypotheses, in [0, 1]

    def add(self, gid: np.ndarray, hid: np.ndarray, d: np.ndarray, radius: float) -> None:
        """One frame: ids and distances d (metres), scored S = max(0, 1 - d / radius). A frame with neither
        targets nor hypotheses is left out: it changes no HOTA figure."""
        if not len(gid) and not len(hid):
            return
        self.gt_ids.append(np.asarray(gid, np.int64))
        self.hyp_ids.append(np.asarray(hid, np.int64))
        self.similarity.append(np.clip(1.0 - np.asarray(d, np.float64) / radius, 0.0, 1.0))


def _dense(ids: list[np.ndarray]) -> tuple[list[np.ndarray], int]:
    """Ids renumbered 0..n-1 (TrackEval indexes arrays by id), and n."""
    flat = np.concatenate(ids) if ids else np.zeros(0, np.int64)
    uniq = np.unique(flat)
    return [np.searchsorted(uniq, i) for i in ids], len(uniq)


def hota(frames: HotaFrames) -> dict[str, float | None]:
    """HOTA, DetA, AssA and LocA (TrackEval's HOTA metric, means over alpha; see the module docstring) of
    one sequence; None where undefined (no targets and no hypotheses; LocA: no match)."""
    from trackeval.metrics.hota import HOTA

    gt_ids, n_gt = _dense(frames.gt_ids)
    hyp_ids, n_hyp = _dense(frames.hyp_ids)
    n_gt_dets, n_hyp_dets = sum(map(len, gt_ids)), sum(map(len, hyp_ids))
    if n_gt_dets == 0 and n_hyp_dets == 0:
        return dict.fromkeys(HOTA_METRICS)
    data = {
        "num_gt_dets": n_gt_dets,
        "num_tracker_dets": n_hyp_dets,
        "num_gt_ids": n_gt,
        "num_tracker_ids": n_hyp,
        "gt_ids": gt_ids,
        "tracker_ids": hyp_ids,
        "similarity_scores": frames.similarity,
    }
    res = HOTA().eval_sequence(data)
    matched = bool(res["HOTA_TP"][0] > 0)
    return {
        "hota": float(np.mean(res["HOTA"])),
        "deta": float(np.mean(res["DetA"])),
        "assa": float(np.mean(res["AssA"])),
        "loca": float(np.mean(res["LocA"])) if matched else None,
    }


Progress = Callable[[int, int, str], None]  # (frames done, frames, stage)


def _score(
    gt: Frames, hyps: Frames, radius: float, codes: list[int | None], progress: Progress | None = None
) -> tuple[list, list[HotaFrames]]:
    """A motmetrics accumulator and the HOTA frames per class code (None: every class) over frames aligned
    one to one (hyps from aligned_hypotheses); `progress(done, total, "matching")` counts frames."""
    import motmetrics as mm

    accs = [mm.MOTAccumulator(auto_id=False) for _ in codes]
    gathered = [HotaFrames() for _ in codes]
    n = len(gt.stamps)
    for k in range(n):
        for acc, hf, code in zip(accs, gathered, codes, strict=True):
            gid, hid, d = _pairs(gt, hyps, k, code)
            hf.add(gid, hid, d, radius)
            d[d > radius] = np.nan
            acc.update(gid.tolist(), hid.tolist(), d, frameid=k)
        if progress is not None and (k + 1) % PROGRESS_EVERY == 0:
            progress(k + 1, n, "matching")
    if progress is not None:
        progress(n, n, "matching")
    return accs, gathered


def evaluate(
    gt: Frames,
    hyps: Frames,
    *,
    regions: Regions | None = None,
    match_radius: float = 0.5,
    stamp_tolerance_ns: int = 0,
    progress: Progress | None = None,
) -> dict:
    """CLEAR-MOT, identity and HOTA figures, overall ("all") and per mover class present among the targets
    or the hypotheses. Returns {name: {metric: value}} with the metrics in METRICS and HOTA_METRICS (counts
    as ints, MOTP in metres, ratios in [0, 1] except MOTA, which can be negative; None where undefined);
    "all" also has `ignored_hypotheses` (in don't-care regions) and `frames_without_tracks`.
    `progress(done, total, stage)` counts ground-truth frames: stage "matching" as they are matched (per
    PROGRESS_EVERY frames), then "HOTA <class>" at 0 and at the total around each class's HOTA."""
    require_scoring()
    import motmetrics as mm

    if not match_radius > 0:
        raise ValueError(f"match radius must be > 0 m, got {match_radius}")
    missing = int(np.sum(align(gt, hyps, stamp_tolerance_ns) < 0))
    hy, ignored = aligned_hypotheses(
        gt, hyps, regions=regions, match_radius=match_radius, stamp_tolerance_ns=stamp_tolerance_ns
    )
    present = set(gt.cls.tolist()) | set(hy.cls.tolist())
    names = ["all"] + [name for code, name in MOVER_CLASSES.items() if code in present]
    codes = [None] + [code for code in MOVER_CLASSES if code in present]
    accs, gathered = _score(gt, hy, match_radius, codes, progress)
    df = mm.metrics.create().compute_many(accs, metrics=METRICS, names=names, generate_overall=False)
    out = {}
    for name, hf in zip(names, gathered, strict=True):
        row: dict[str, float | int | None] = {}
        for m in METRICS:
            v = df.loc[name, m]
            if m.startswith("num_") or m in ("mostly_tracked", "partially_tracked", "mostly_lost"):
                row[m] = int(v)
            else:
                row[m] = float(v) if np.isfinite(v) else None
        if progress is not None:
            progress(0, len(gt.stamps), f"HOTA {name}")
        row.update(hota(hf))
        if progress is not None:
            progress(len(gt.stamps), len(gt.stamps), f"HOTA {name}")
        out[name] = row
    out["all"]["ignored_hypotheses"] = ignored
    out["all"]["frames_without_tracks"] = missing
    return out
