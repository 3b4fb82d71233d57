"""Scoring tracks against ground truth: CLEAR-MOT (MOTA, MOTP), IDF1 and their counts with py-motmetrics, HOTA
(DetA, AssA, LocA) with TrackEval.

What is scored (pure functions over arrays; positions in the sensor frame, metres):
- Targets: ground-truth objects of a mover class (person, circle object, rectangular object:
  GroundTruthObject.CLASS_* 1-3) that move at some time in the run, in the scans where at least one beam
  hits them (`visible`). `include_occluded=True` scores them in every scan, hidden or not.
- Don't-care regions: every other ground-truth object, i.e. scene structure (columns, benches, wall
  corners, walls), movers that never move (a parked platform, a person standing all along) and, by
  default, hidden targets. A track within the match radius of one of them (its extent: an oriented
  length x width rectangle, a segment for walls, a point for corners) and not within the match radius of a
  target is ignored: neither a match nor a false positive (like MOTChallenge's distractors).
- Hypotheses: confirmed tracks (STATUS_CONFIRMED), and coasting ones too with `include_occluded`;
  `exclude_static=True` drops tracks the tracker classifies static.
- Matching: a hypothesis may match a target within `match_radius` metres (Euclidean, sensor frame of the
  scan); motmetrics solves each frame's assignment and keeps previous matches. MOTP is the mean distance
  of matched pairs, metres (lower is better).
- Frames: every ground-truth message (or CSV stamp) is a frame; tracks come from the Tracks message with
  the same stamp (or the nearest within `stamp_tolerance_ns`).
- Per class: targets of class c against hypotheses whose track class is c (Track and GroundTruthObject
  class codes coincide: 1 person, 2 circle object, 3 rectangular object). Tracks of class unknown count
  only in the overall figures.
- HOTA (Luiten et al. 2021, IJCV; TrackEval's implementation): the same targets, hypotheses and frames,
  with the similarity of a target and a hypothesis at distance d metres S = max(0, 1 - d / match_radius)
  (1 on the target, 0 at the match radius and beyond, so no pair farther than CLEAR-MOT's radius matches).
  HOTA, DetA, AssA and LocA are TrackEval's means over the localisation thresholds alpha = 0.05, 0.10, ...,
  0.95: a pair counts as a true positive at alpha when S >= alpha. LocA is then the mean S of matched pairs,
  i.e. 1 - (mean matched distance) / match_radius; it is None when nothing matches. With neither targets
  nor hypotheses HOTA, DetA and AssA are None (undefined), like MOTA without targets.
CSV ground truth (annotated real logs) has targets only: every annotated object, no don't-care regions.

Memory: scoring holds the whole run, and does not stream like the other commands. py-motmetrics'
MOTAccumulator keeps every frame's events (a DataFrame row per match, miss, false positive and switch)
and computes the figures from all of them at the end; IDF1 in particular is one assignment of ground-truth
ids to track ids over the whole run. Feeding the accumulator block by block would save only the decoded
messages (a few numbers per object and frame, next to the accumulator's rows), and which targets count
(`moved_ids`: movers that move at some time) is itself a whole-run fact. Bounding it would mean computing
CLEAR-MOT and IDF1 here from per-id counts instead of motmetrics' events; not done. HOTA likewise needs
the whole run (its matching weighs each pair by the two ids' alignment over all frames): it keeps each
frame's targets x hypotheses similarities, a few numbers per frame.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .extras import require
from .log.vocabulary import CLASS_NAMES, CLASS_PERSON, CLASS_UNKNOWN, MOBILITY_STATIC, STATUS_COASTING, STATUS_CONFIRMED

MOVER_CLASSES = {code: name for code, name in CLASS_NAMES.items() if code != CLASS_UNKNOWN}
# a ground-truth CSV's class: the name, with underscores or its first word ("circle"), or "people"
CLASS_BY_NAME = {
    "people": CLASS_PERSON,
    **{
        alias: code for code, name in MOVER_CLASSES.items() for alias in (name, name.replace(" ", "_"), name.split()[0])
    },
}
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


@dataclass
class Frames:
    """Positions per frame: frame k's objects are rows offsets[k]:offsets[k + 1] of ids, x, y, cls."""

    stamps: np.ndarray  # (N,) int64 ns
    offsets: np.ndarray  # (N + 1,) int64
    ids: np.ndarray  # (M,) int64
    x: np.ndarray  # (M,) float64, m, sensor frame
    y: np.ndarray
    cls: np.ndarray  # (M,) int64 class code; 0 when unknown

    def select(self, keep: np.ndarray) -> Frames:
        """The same frames with only the rows where `keep` is true."""
        frame = np.repeat(np.arange(len(self.stamps)), np.diff(self.offsets))
        counts = np.bincount(frame[keep], minlength=len(self.stamps))
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return Frames(self.stamps, offsets, self.ids[keep], self.x[keep], self.y[keep], self.cls[keep])


@dataclass
class Regions:
    """Don't-care regions per frame (oriented rectangles, sensor frame, m): frame k's are rows
    offsets[k]:offsets[k + 1]."""

    offsets: np.ndarray
    x: np.ndarray
    y: np.ndarray
    angle: np.ndarray  # rad, of the rectangle's length axis
    half_length: np.ndarray
    half_width: np.ndarray

    def near(self, k: int, px: np.ndarray, py: np.ndarray, radius: float) -> np.ndarray:
        """Which points (px, py) are within `radius` of a region of frame k."""
        r = slice(self.offsets[k], self.offsets[k + 1])
        if not len(px) or self.offsets[k] == self.offsets[k + 1]:
            return np.zeros(len(px), bool)
        c, s = np.cos(self.angle[r])[:, None], np.sin(self.angle[r])[:, None]
        dx, dy = px[None, :] - self.x[r][:, None], py[None, :] - self.y[r][:, None]
        u = np.maximum(np.abs(c * dx + s * dy) - self.half_length[r][:, None], 0)
        v = np.maximum(np.abs(-s * dx + c * dy) - self.half_width[r][:, None], 0)
        return (np.hypot(u, v) <= radius).any(axis=0)


def _frames(stamps: np.ndarray, offsets: np.ndarray, items: np.ndarray, cls_field: str) -> Frames:
    return Frames(
        np.asarray(stamps, np.int64),
        np.asarray(offsets, np.int64),
        items["id"].astype(np.int64),
        items["x"].astype(np.float64),
        items["y"].astype(np.float64),
        items[cls_field].astype(np.int64),
    )


def moved_ids(objects: np.ndarray) -> np.ndarray:
    """Ids (int64, sorted) of the GroundTruthObject elements of a mover class that move in at least one of
    them: over a whole run, the movers that can be targets."""
    mover = np.isin(objects["classification"], list(MOVER_CLASSES))
    return np.unique(objects["id"][mover & objects["moving"].astype(bool)].astype(np.int64))


def target_mask(objects: np.ndarray, moved: np.ndarray, *, include_occluded: bool = False) -> np.ndarray:
    """Which GroundTruthObject elements are targets: a mover class, an id in `moved` (moved_ids of the whole
    run) and, unless `include_occluded`, hit by a beam in that scan."""
    target = np.isin(objects["classification"], list(MOVER_CLASSES)) & np.isin(objects["id"].astype(np.int64), moved)
    if not include_occluded:
        target &= objects["visible"].astype(bool)
    return target


def ground_truth_frames(
    stamps: np.ndarray,
    offsets: np.ndarray,
    objects: np.ndarray,
    sensor_theta: np.ndarray | None = None,
    *,
    include_occluded: bool = False,
) -> tuple[Frames, Regions]:
    """Targets and don't-care regions of GroundTruth messages (see the module docstring): `objects` are
    GroundTruthObject elements, message k's at offsets[k]:offsets[k + 1]; sensor_theta (rad, per message)
    turns the objects' world orientations into the sensor frame (zero when None)."""
    f = _frames(stamps, offsets, objects, "classification")
    target = target_mask(objects, moved_ids(objects), include_occluded=include_occluded)
    theta = np.zeros(len(stamps)) if sensor_theta is None else np.asarray(sensor_theta, np.float64)
    frame = np.repeat(np.arange(len(stamps)), np.diff(f.offsets))
    other = ~target
    counts = np.bincount(frame[other], minlength=len(stamps))
    regions = Regions(
        np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        f.x[other],
        f.y[other],
        objects["orientation"][other].astype(np.float64) - theta[frame[other]],
        objects["length"][other].astype(np.float64) / 2,
        objects["width"][other].astype(np.float64) / 2,
    )
    return f.select(target), regions


def track_frames(
    stamps: np.ndarray,
    offsets: np.ndarray,
    tracks: np.ndarray,
    *,
    include_coasting: bool = False,
    exclude_static: bool = False,
) -> Frames:
    """Frames of the hypotheses in Tracks messages (see the module docstring for which tracks count)."""
    f = _frames(stamps, offsets, tracks, "classification")
    status = tracks["status"]
    keep = (status == STATUS_CONFIRMED) | ((status == STATUS_COASTING) if include_coasting else False)
    if exclude_static:
        keep &= tracks["mobility"] != MOBILITY_STATIC
    return f.select(np.asarray(keep, bool))


INT64_MAX = np.iinfo(np.int64).max


def read_ground_truth_csv(path, name: str | None = None) -> Frames:
    """Ground truth from a CSV file (see parse_ground_truth_csv): UTF-8 text, a leading byte-order mark
    allowed (spreadsheets write one). A binary file, text that is not UTF-8, or a file that cannot be read
    raises InputError naming it."""
    from .input_files import MAX_GROUND_TRUTH_BYTES, read_bytes

    name = name or str(path)
    data = read_bytes(path, MAX_GROUND_TRUTH_BYTES, "ground-truth CSV file", name=name)
    if b"\x00" in data:
        raise InputError(f"{name}: binary data (a NUL byte at byte {data.index(0)}), not a CSV text file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{name}: not UTF-8 text (byte {exc.start}), not a CSV text file") from None
    return parse_ground_truth_csv(text, name)


def parse_ground_truth_csv(text: str, name: str = "ground truth") -> Frames:
    """Ground truth from CSV text with a header `stamp_ns,id,x,y` (sensor frame, m) and an optional
    `class` column (person, circle, rectangular or 1-3; empty: unknown). A row with an empty id marks an
    annotated scan with no objects in it. Frames are the distinct stamps, in ascending order.

    Refused with InputError naming the line: a stamp that is not an integer of int64 nanoseconds, an id
    that is not an integer, a position that is not a finite number, a class that is none of those, and an
    id twice at one stamp (one object cannot be in two places at once)."""
    text = text.removeprefix("\ufeff")
    try:
        reader = csv.DictReader(io.StringIO(text))
        cols = {c.strip().lower(): c for c in reader.fieldnames or [] if c is not None}
        missing = [c for c in ("stamp_ns", "id", "x", "y") if c not in cols]
        if missing:
            raise InputError(f"{name}: CSV needs the columns stamp_ns,id,x,y; missing {','.join(missing)}")
        rows = _csv_rows(reader, cols, name)
    except csv.Error as exc:
        raise InputError(f"{name}: line {reader.line_num}: not CSV ({exc})") from None
    stamps, ids, xs, ys, cls, empty = rows
    if not stamps and not empty:
        raise InputError(f"{name}: no ground-truth rows")
    st = np.array(stamps, np.int64)
    order = np.argsort(st, kind="stable")
    frames = np.unique(np.concatenate([st, np.array(empty, np.int64)]))
    offsets = np.searchsorted(st[order], frames, side="left")
    offsets = np.append(offsets, len(st)).astype(np.int64)
    return Frames(
        frames,
        offsets,
        np.array(ids, np.int64)[order],
        np.array(xs)[order],
        np.array(ys)[order],
        np.array(cls, np.int64)[order],
    )


def _csv_rows(reader: csv.DictReader, cols: dict[str, str], name: str) -> tuple[list, ...]:
    """(stamps, ids, xs, ys, classes, stamps of empty rows) of the CSV's rows, each checked."""
    stamps, ids, xs, ys, cls, empty = [], [], [], [], [], []
    seen: dict[tuple[int, int], int] = {}  # (stamp, id) -> line
    for row in reader:
        line = reader.line_num
        cell = _cells(row, cols)
        stamp = _integer(cell("stamp_ns"), "stamp_ns", name, line)
        if not 0 <= stamp <= INT64_MAX:
            raise InputError(f"{name}: line {line}: stamp_ns {stamp} is outside int64 nanoseconds (0 to {INT64_MAX})")
        raw_id = cell("id")
        if not raw_id:
            empty.append(stamp)
            continue
        ident = _integer(raw_id, "id", name, line)
        if not -INT64_MAX <= ident <= INT64_MAX:
            raise InputError(f"{name}: line {line}: id {ident} is outside int64")
        x, y = (_finite(cell(c), c, name, line) for c in ("x", "y"))
        c = cell("class").lower()
        code = int(c) if c.isascii() and c.isdigit() else CLASS_BY_NAME.get(c, -1) if c else 0
        if code not in MOVER_CLASSES and c:
            raise InputError(f"{name}: line {line}: unknown class {c!r} (person, circle, rectangular, 1-3 or empty)")
        if (stamp, ident) in seen:
            raise InputError(
                f"{name}: line {line}: id {ident} again at stamp_ns {stamp} (first at line "
                f"{seen[stamp, ident]}); one object per id and frame"
            )
        seen[stamp, ident] = line
        stamps.append(stamp)
        ids.append(ident)
        xs.append(x)
        ys.append(y)
        cls.append(code)
    return stamps, ids, xs, ys, cls, empty


def _cells(row: dict, cols: dict[str, str]):
    return lambda col: (row.get(cols[col]) or "").strip() if col in cols else ""


def _integer(text: str, col: str, name: str, line: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(f"{name}: line {line}: {col} {text!r} is not an integer") from None


def _finite(text: str, col: str, name: str, line: int) -> float:
    """A position cell, metres: a finite number."""
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{name}: line {line}: {col} {text!r} is not a number") from None
    if not np.isfinite(v):
        raise InputError(f"{name}: line {line}: {col} is {text}; positions must be finite (metres)")
    return v


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
        row = {}
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


def frames_from_channels(
    gt_stamps: np.ndarray,
    gt_offsets: np.ndarray,
    gt_objects: np.ndarray,
    gt_sensor_theta: np.ndarray | None,
    tr_stamps: np.ndarray,
    tr_offsets: np.ndarray,
    tr_items: np.ndarray,
    *,
    include_occluded: bool = False,
    exclude_static: bool = False,
) -> tuple[Frames, Regions, Frames]:
    """Targets, don't-care regions and hypotheses from decoded GroundTruth and Tracks messages."""
    gt, regions = ground_truth_frames(
        gt_stamps, gt_offsets, gt_objects, gt_sensor_theta, include_occluded=include_occluded
    )
    hy = track_frames(tr_stamps, tr_offsets, tr_items, include_coasting=include_occluded, exclude_static=exclude_static)
    return gt, regions, hy
