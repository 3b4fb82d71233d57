"""What evaluate scores, as arrays per frame (see the package docstring): targets and hypotheses (`Frames`),
don't-care regions (`Regions`), from decoded GroundTruth and Tracks messages. Positions in the sensor frame, m."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..logs.vocabulary import CLASS_NAMES, CLASS_UNKNOWN, MOBILITY_STATIC, STATUS_COASTING, STATUS_CONFIRMED

MOVER_CLASSES = {code: name for code, name in CLASS_NAMES.items() if code != CLASS_UNKNOWN}


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
