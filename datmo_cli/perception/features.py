"""Segmentation and features of a whole run: the functions behind `datmo segment`, `datmo features` and
the one pass of `datmo run`.

`segment_run` and `extract_run` validate the run and call the numba kernels block by block; results are
flat arrays with per-scan offsets (RunFeatures). The pipeline layer's `feature_channels` turns them into the
channels the commands write: /datmo/segments, /datmo/features, /datmo/landmarks and
/datmo/markers/features. Sensor frame of each scan (x forward, y left), metres and radians; landmarks in
the odometry (world) frame when the run has odometry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from datmo_cli.base import libm

from ..base.errors import InputError
from ..logs import cdr, types
from ..logs.scan import Odometry, ScanRun
from . import scan_extractor as SX
from . import segmentation
from .feature_layout import ExtractSetup
from .landmark_database import LandmarkDatabase, LandmarkStream
from .landmarks import (
    circle_detections,
    junction_detections,
    line_end_detections,
    seat_detections,
    to_world,
)
from .params import FeatureParams

LINE_DTYPE = cdr.element_dtype(types.LINE)
CIRCLE_DTYPE = cdr.element_dtype(types.CIRCLE)
BLOB_DTYPE = cdr.element_dtype(types.BLOB)
LEG_DTYPE = cdr.element_dtype(types.LEG)
NO_SEGMENT = 0xFFFFFFFF  # Leg.segment of a leg cluster no segment holds the middle of
BLOCK = 256  # scans per kernel call: bounds the scratch memory and paces progress reports


@dataclass
class RunFeatures:
    """Segments and features of every scan, as flat arrays with per-scan offsets (N + 1 each).

    Scan k's segments are seg_start/seg_end[seg_offsets[k]:seg_offsets[k + 1]] (beam index ranges
    [start, end)); its lines are lines[line_offsets[k]:line_offsets[k + 1]] (element_dtype(LINE)), and so
    on for circles, blobs and legs (the segments the leg detector takes for legs; none with the paper's
    rule). `landmarks` is the run's landmark database (None when not computed).
    """

    stamps: np.ndarray
    frame_id: str
    seg_start: np.ndarray
    seg_end: np.ndarray
    seg_offsets: np.ndarray
    lines: np.ndarray
    line_offsets: np.ndarray
    circles: np.ndarray
    circle_offsets: np.ndarray
    blobs: np.ndarray
    blob_offsets: np.ndarray
    landmarks: LandmarkDatabase | None = None
    landmark_frame: str = ""
    legs: np.ndarray | None = None
    leg_offsets: np.ndarray | None = None
    range_limits: tuple[float, float] = (0.0, np.inf)  # valid returns (m): range_min and range_max
    angles: np.ndarray | None = None  # (B,) beam angles, rad

    def __post_init__(self) -> None:
        if self.legs is None:
            self.legs = np.zeros(0, LEG_DTYPE)
            self.leg_offsets = np.zeros(len(self.stamps) + 1, np.int64)

    def __len__(self) -> int:
        return len(self.stamps)

    def counts(self) -> dict[str, float]:
        """Mean segments, lines, circles and blobs per scan."""
        n = max(len(self), 1)
        return {
            "segments": len(self.seg_start) / n,
            "lines": len(self.lines) / n,
            "circles": len(self.circles) / n,
            "blobs": len(self.blobs) / n,
            "legs": len(self.legs) / n,
        }


def _check(run: ScanRun) -> None:
    g = run.geometry
    if not np.isfinite(g.angle_increment) or g.angle_increment == 0:
        raise InputError(f"scan geometry has an unusable angle increment ({g.angle_increment!r} rad)")


def _c1(run: ScanRun) -> float:
    """C1 = sqrt(2 (1 - cos delta_alpha)): the chord of the scan's angle step at unit range."""
    return float(np.sqrt(2.0 * (1.0 - libm.cos(run.geometry.angle_increment))))


def _range_limits(run: ScanRun) -> tuple[float, float]:
    g = run.geometry
    lo = float(g.range_min) if np.isfinite(g.range_min) else 0.0
    hi = float(g.range_max) if np.isfinite(g.range_max) and g.range_max > lo else np.inf
    return lo, hi


def _offsets(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def segment_run(run: ScanRun, params: FeatureParams | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments of every scan: (start, end, offsets); scan k's are start/end[offsets[k]:offsets[k + 1]]."""
    p = params or FeatureParams()
    _check(run)
    lo, hi = _range_limits(run)
    ranges = np.ascontiguousarray(run.ranges, np.float32)
    N, B = ranges.shape if ranges.ndim == 2 else (0, 0)
    # a scan has at most B // min_points segments (each of at least min_points beams)
    seg = np.empty((max(N * (B // max(p.min_points, 1) + 1), 1), 2), np.int64)
    count = np.zeros(N, np.int64)
    if N and B:
        n = segmentation.segment_block(
            ranges, float(libm.cos(run.geometry.angle_increment)), p.c0, _c1(run), lo, hi, p.min_points, seg, count
        )
        seg = seg[:n]
    else:
        seg = seg[:0]
    return seg[:, 0].astype(np.uint32), seg[:, 1].astype(np.uint32), _offsets(count)


def _rows_to(dtype: np.dtype, rows: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    out = np.zeros(len(rows), dtype)
    for col, name in enumerate(names, start=1):
        if name:
            out[name] = rows[:, col]
    return out


_LINE_NAMES = (
    "segment",
    "first",
    "last",
    "n_points",
    "x_ini",
    "y_ini",
    "x_end",
    "y_end",
    "rho",
    "theta",
    "length",
    "r_acc",
)
_CIRCLE_NAMES = ("segment", "first", "last", "n_points", "x", "y", "radius", "r_acc")
_BLOB_NAMES = ("segment", "first", "last", "n_points", "x", "y", "size", "kind")
_LEG_NAMES = ("segment", "first", "last", "n_points", "x", "y", "width", "probability")


def _check_segments(start: np.ndarray, end: np.ndarray, offsets: np.ndarray, beams: int) -> None:
    """Given segments, beam ranges [start, end) clipped to the scan (empty ones are skipped), must be disjoint
    and in scan order: more segments than beams would not fit the kernels' buffers."""
    if len(offsets) and (offsets[0] != 0 or offsets[-1] != len(start) or np.any(np.diff(offsets) < 0)):
        raise InputError("segment offsets do not index the segment arrays")
    start = np.clip(start, 0, beams)
    end = np.clip(end, start, beams)
    bad = np.zeros(len(start), bool)
    first = np.zeros(len(start), bool)
    first[offsets[:-1][offsets[:-1] < len(start)]] = True
    bad[1:] |= ~first[1:] & (start[1:] < end[:-1])
    if bad.any():
        i = int(np.argmax(bad))
        scan = int(np.searchsorted(offsets, i, side="right") - 1)
        raise InputError(
            f"segment [{start[i]}, {end[i]}) of scan {scan} overlaps the one before: "
            "segments must be disjoint and in scan order"
        )


def _leg_rows(
    block: np.ndarray,
    cos_a: np.ndarray,
    sin_a: np.ndarray,
    seg: np.ndarray,
    count: np.ndarray,
    lo: float,
    hi: float,
    angles: np.ndarray,
    model,
    threads: int = 1,
) -> np.ndarray:
    """Rows (scan in block, segment in scan, first, last, n, x, y, width, probability) of the block's
    clusters (those legs.LegModel `model` scores: the segments, or leg_tracker's gap clusters) it gives a leg
    probability above 0 (every leg candidate, weak or strong: the tracker takes the model's threshold_p); x, y
    the centroid (sensor frame, m); segment: the segment holding the cluster's middle beam (NO_SEGMENT when none
    does). The detector runs on `threads` threads (the same rows for any count)."""
    from .legs import leg_probabilities, model_clusters

    seg_off = _offsets(count)
    seg_start, seg_end = seg[: seg_off[-1], 0], seg[: seg_off[-1], 1]
    start, end, off = model_clusters(block, angles, lo, hi, model, seg_start, seg_end, seg_off)
    prob = leg_probabilities(block, angles, start, end, off, lo, hi, model, threads)
    hit = np.flatnonzero(prob > 0.0)
    rows = np.zeros((len(hit), 9))
    if not len(hit):
        return rows
    scan = np.searchsorted(off, hit, side="right") - 1
    s, e = start[hit].astype(np.int64), end[hit].astype(np.int64)
    B = block.shape[1]
    # the segment under each cluster's middle beam (segments are in scan order: global beam indices sort)
    segment = np.full(len(hit), NO_SEGMENT, np.int64)  # a cluster may stand where no segment is kept
    if len(seg_start):
        seg_scan = np.searchsorted(seg_off, np.arange(len(seg_start)), side="right") - 1
        g0, g1 = seg_scan * B + seg_start, seg_scan * B + seg_end
        mid = scan * B + (s + e - 1) // 2
        j = np.maximum(np.searchsorted(g0, mid, side="right") - 1, 0)
        inside = (g0[j] <= mid) & (mid < g1[j])
        segment = np.where(inside, j - seg_off[seg_scan[j]], NO_SEGMENT)
    r = np.where(np.isfinite(block), block, 0.0).astype(np.float64)  # segments hold valid returns only
    px, py = r * cos_a, r * sin_a
    # sums over [s, e) of each hit: segments are disjoint and in scan order, so the bounds interleave sorted
    bounds = np.empty(2 * len(hit), np.int64)
    bounds[0::2], bounds[1::2] = scan * B + s, scan * B + e
    n = (e - s).astype(np.float64)
    sx = np.add.reduceat(np.append(px.ravel(), 0.0), bounds)[0::2]
    sy = np.add.reduceat(np.append(py.ravel(), 0.0), bounds)[0::2]
    x0, y0, x1, y1 = px[scan, s], py[scan, s], px[scan, e - 1], py[scan, e - 1]
    rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4] = scan, segment, s, e - 1, n
    rows[:, 5], rows[:, 6] = sx / n, sy / n
    rows[:, 7], rows[:, 8] = np.hypot(x1 - x0, y1 - y0), prob[hit]
    return rows


def _row_buffers(n: int, B: int) -> tuple[np.ndarray, ...]:
    """The kernels' row buffers for blocks of up to n scans of B beams: segments (n B, 2), lines (n B, 13),
    circles and blobs (n B, 9). empty, not zeros: only the rows the kernel fills are read; made once a run,
    so the pages a block writes are mapped once, not once a block."""
    rows = n * B  # a scan has at most B segments, lines, circles and blobs (disjoint beam ranges)
    return tuple(np.empty((rows, c), np.int64 if c == 2 else np.float64) for c in (2, 13, 9, 9))


def _extract_block(
    block: np.ndarray,
    setup: ExtractSetup,
    given: np.ndarray,
    given_off: np.ndarray,
    threads: int,
    buffers: tuple[np.ndarray, ...] | None = None,
) -> tuple[np.ndarray, ...]:
    """The perception kernels on one block of scans (ranges (n, B), m; `setup` the kernels' geometry and
    parameters) on `threads` threads (a threads.resolve()d count): (segments (S, 2) beam ranges [start, end),
    segments per scan (n,), line rows (L, 13), circle rows (C, 9), blob rows (Cb, 9)) in scan order, column 0
    the scan in the block.
    Each scan's rows are written to its own stretch of B rows, so the result is the same for any `threads`.
    `buffers`: _row_buffers of at least n scans to write into (made here when None)."""
    from . import threads as TH

    n, B = block.shape
    if buffers is None or len(buffers[0]) < n * B:
        buffers = _row_buffers(n, B)
    seg, lines, circles, blobs = (b[: n * B] for b in buffers)
    counts = np.zeros((n, 4), np.int64)
    threads = TH.for_scans(threads, n)
    if threads > 1:
        with TH.numba_threads(threads):
            SX.extract_parallel(
                block, min(n, 4 * threads), setup, (seg, lines, circles, blobs, counts), (given, given_off)
            )
    else:
        SX.extract_scans(block, 0, n, setup, (seg, lines, circles, blobs, counts), (given, given_off))
    out = []
    for j, rows in enumerate((seg, lines, circles, blobs)):
        kept = np.empty((int(counts[:, j].sum()), rows.shape[1]), rows.dtype)
        SX.gather_rows(rows, counts, j, B, kept)
        out.append(kept)
    return out[0], counts[:, 0].copy(), out[1], out[2], out[3]


def extract_run(
    run: ScanRun,
    params: FeatureParams | None = None,
    odometry: Odometry | None = None,
    *,
    landmarks: bool = True,
    segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    progress: Callable[[int, int], None] | None = None,
    threads: int | None = None,
    landmark_stream: LandmarkStream | None = None,
) -> RunFeatures:
    """Segment every scan and extract its lines, circles and blobs (HTL, HTC and the section 5.2 rule);
    with `landmarks`, also build the landmark database (world frame when `odometry` is given), continuing
    `landmark_stream` when given (the database of the scans before this run's, block by block).
    `segments` (start, end, offsets as segment_run gives them, e.g. a log's /datmo/segments) are used
    instead of segmenting. The leg detector `params.leg_model` names (see perception.legs) marks the
    segments it takes for legs. `progress(done, total)` is called after each block of scans. `threads`: how
    many threads the per-scan work runs on (None: the process's default, all cores unless `--threads` set
    it; 0: all cores; see perception.threads); the results are the same for any count."""
    from . import threads as TH
    from .leg_model import load_leg_model

    p = params or FeatureParams()
    model = load_leg_model(p.leg_model)
    _check(run)
    lo, hi = _range_limits(run)
    ranges = np.ascontiguousarray(run.ranges, np.float32)
    N, B = ranges.shape if ranges.ndim == 2 else (0, 0)
    angles = run.geometry.angles().astype(np.float64) if B else np.zeros(0)
    cos_a, sin_a = libm.cos(angles), libm.sin(angles)
    nt = max(int(round(180.0 / p.theta_resolution)), 1)
    theta = np.arange(nt) * (np.pi / nt)
    cos_t, sin_t = libm.cos(theta), libm.sin(theta)
    vec = p.kernel_vector()
    cos_inc, c1 = float(libm.cos(run.geometry.angle_increment)), _c1(run)
    if segments is not None:
        g_start, g_end, g_off = (np.asarray(v, np.int64) for v in segments)
        if len(g_off) != N + 1:
            raise InputError(f"segments for {len(g_off) - 1} scans, the run has {N}")
        _check_segments(g_start, g_end, g_off, B)
        given = np.stack([g_start, g_end], axis=1) if len(g_start) else np.zeros((0, 2), np.int64)
    segs, seg_counts, parts = [], [], {"l": [], "c": [], "b": [], "g": []}
    n_threads = TH.resolve(threads)
    setup = ExtractSetup(
        cos_a=cos_a,
        sin_a=sin_a,
        cos_inc=cos_inc,
        c1=c1,
        range_min=lo,
        range_max=hi,
        params=vec,
        cos_t=cos_t,
        sin_t=sin_t,
    )
    buffers = _row_buffers(min(N, BLOCK), B) if N and B else None
    for a in range(0, N, BLOCK):
        block = ranges[a : a + BLOCK]
        n = len(block)
        if segments is not None:
            sub_off = g_off[a : a + n + 1]
            block_given, block_off = given[sub_off[0] : sub_off[-1]], sub_off - sub_off[0]
        else:
            block_given, block_off = np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
        if B:
            seg, count, lines, circles, blobs = _extract_block(block, setup, block_given, block_off, n_threads, buffers)
        else:
            seg, count = np.zeros((0, 2), np.int64), np.zeros(n, np.int64)
            lines, circles, blobs = np.zeros((0, 13)), np.zeros((0, 9)), np.zeros((0, 9))
        segs.append(seg)
        seg_counts.append(count)
        legs = (
            _leg_rows(block, cos_a, sin_a, seg, count, lo, hi, angles, model, n_threads)
            if model is not None and B
            else None
        )
        for key, rows in (("l", lines), ("c", circles), ("b", blobs)):
            rows[:, 0] += a
            parts[key].append(rows)
        if legs is not None:
            legs[:, 0] += a
            parts["g"].append(legs)
        if progress is not None:
            progress(a + n, N)
    seg = np.concatenate(segs) if segs else np.zeros((0, 2), np.int64)
    count = np.concatenate(seg_counts) if seg_counts else np.zeros(0, np.int64)
    rows = {k: (np.concatenate(v) if v else np.zeros((0, 13 if k == "l" else 9))) for k, v in parts.items()}
    leg_scan = rows["g"][:, 0].astype(np.int64)
    out = RunFeatures(
        stamps=run.stamps,
        frame_id=run.geometry.frame_id,
        seg_start=seg[:, 0].astype(np.uint32),
        seg_end=seg[:, 1].astype(np.uint32),
        seg_offsets=_offsets(count),
        lines=_rows_to(LINE_DTYPE, rows["l"], _LINE_NAMES),
        line_offsets=_offsets(np.bincount(rows["l"][:, 0].astype(np.int64), minlength=N)),
        circles=_rows_to(CIRCLE_DTYPE, rows["c"], _CIRCLE_NAMES),
        circle_offsets=_offsets(np.bincount(rows["c"][:, 0].astype(np.int64), minlength=N)),
        blobs=_rows_to(BLOB_DTYPE, rows["b"], _BLOB_NAMES),
        blob_offsets=_offsets(np.bincount(rows["b"][:, 0].astype(np.int64), minlength=N)),
        legs=_rows_to(LEG_DTYPE, rows["g"], _LEG_NAMES),
        leg_offsets=_offsets(np.bincount(leg_scan, minlength=N)),
        range_limits=(lo, hi),
        angles=angles,
    )
    if landmarks:
        out.landmarks, out.landmark_frame = (
            LandmarkDatabase(*_world_detections(out, ranges, odometry, p), p, stream=landmark_stream),
            (odometry.frame_id if odometry is not None and len(odometry) else run.geometry.frame_id),
        )
    return out


def _world_detections(
    f: RunFeatures, ranges: np.ndarray, odometry: Odometry | None, p: FeatureParams
) -> tuple[np.ndarray, np.ndarray]:
    """(landmark detections of `f`'s scans (rows DET_*, scans counted from f's first), in the odometry frame
    when there is odometry, else the sensor frame; f's stamps)."""
    n = len(f)
    lo, hi = f.range_limits
    line_scan = np.repeat(np.arange(n), np.diff(f.line_offsets))
    circle_scan = np.repeat(np.arange(n), np.diff(f.circle_offsets))
    det = np.concatenate(
        [
            junction_detections(f.lines, line_scan, p),
            line_end_detections(f.lines, line_scan, f.seg_start, f.seg_end, f.seg_offsets, ranges, (lo, hi), p),
            circle_detections(
                f.circles,
                circle_scan,
                f.lines,
                line_scan,
                f.line_offsets,
                f.seg_start,
                f.seg_end,
                f.seg_offsets,
                ranges,
                (lo, hi),
                p,
            ),
            seat_detections(f.lines, line_scan, f.seg_start, f.seg_end, f.seg_offsets, ranges, (lo, hi), f.angles, p),
        ]
    )
    poses = odometry.at(f.stamps) if odometry is not None and len(odometry) else None
    return to_world(det, poses), f.stamps


def leg_model_provenance(spec: str) -> dict:
    """What an output records of the leg detector `spec` names: the rule, or the model file with its
    SHA-256, decision threshold and what it was trained on (held-out figures included)."""
    from pathlib import Path

    from ..logs.mcapio import sha256_of
    from .leg_model import DEFAULT_MODEL_PATH, load_leg_model

    model = load_leg_model(spec)
    if model is None:
        return {"model": "paper", "rule": "legs are circles of leg radius; a person needs the walking pattern"}
    path = Path(DEFAULT_MODEL_PATH) if spec == "default" else Path(spec)
    trained = {
        k: model.provenance[k] for k in ("estimator", "held_out", "trained_on", "created") if k in model.provenance
    }
    return {
        "model": spec,
        "path": str(path),
        "sha256": sha256_of(path),
        "threshold": model.threshold_p,
        "features": list(model.feature_names),
        "trained": trained,
    }
