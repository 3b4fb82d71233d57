"""The recordings the leg detector learns from: labelled ones (scans with the positions of the legs seen in
each: leg_tracker's positive bags, a geometry_msgs/PoseArray per scan in the laser frame, matched to scans by
log time) and empty ones (scans with no people: every cluster is a negative). Read from ROS 1 bags, ROS 2 bag
folders and MCAP files by log.importers.scans_and_poses. Metres, laser (sensor) frame, times in ns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...base.errors import InputError
from ...logs.importers.scans_and_poses import read_scans_and_poses
from ...logs.scan import ScanRun

LABEL_WINDOW_NS = 50_000_000  # a scan takes the label message logged nearest to it, within this
DEFAULT_LABELS_TOPIC = "/leg_cluster_positions"


@dataclass
class Recording:
    """One scanner's scans from one file. `legs[k]` holds scan k's labelled legs (K x 2, metres, laser frame);
    `legs` is None for an empty recording (no people: every segment is a negative)."""

    name: str
    path: Path
    topic: str
    run: ScanRun
    legs: list[np.ndarray] | None = None

    @property
    def labelled(self) -> bool:
        return self.legs is not None


def thinned(rec: Recording, step: int = 2) -> Recording:
    """`rec` as a scanner `step` times coarser would see it: every step-th beam (from the first), the angle
    increment step times as wide; the labels (laser frame) are unchanged."""
    import dataclasses

    g = rec.run.geometry
    ranges = rec.run.ranges[:, ::step]
    geometry = dataclasses.replace(g, angle_increment=g.angle_increment * step, n_beams=ranges.shape[1])
    return Recording(
        f"{rec.name} thinned {step}x", rec.path, rec.topic, ScanRun(rec.run.stamps, ranges, geometry), rec.legs
    )


def match_labels(
    scan_log_times: np.ndarray, label_times: np.ndarray, labels: Sequence[np.ndarray], window_ns: int = LABEL_WINDOW_NS
) -> list[np.ndarray]:
    """Each scan's labelled legs: the label message logged nearest to the scan's log time, when within
    `window_ns` (else none: K = 0). Times in ns; labels K x 2 arrays (metres, laser frame)."""
    empty = np.zeros((0, 2))
    if len(label_times) == 0:
        return [empty for _ in scan_log_times]
    order = np.argsort(label_times, kind="stable")
    lt = np.asarray(label_times, np.int64)[order]
    t = np.asarray(scan_log_times, np.int64)
    j = np.clip(np.searchsorted(lt, t), 1, max(len(lt) - 1, 1))
    before = np.clip(j - 1, 0, len(lt) - 1)
    after = np.clip(j, 0, len(lt) - 1)
    near = np.where(np.abs(lt[before] - t) <= np.abs(lt[after] - t), before, after)
    ok = np.abs(lt[near] - t) <= window_ns
    return [
        np.asarray(labels[order[n]], np.float64).reshape(-1, 2) if k else empty
        for n, k in zip(near.tolist(), ok.tolist(), strict=True)
    ]


def read_labelled(path: str | Path, topic: str | None = None, labels_topic: str = DEFAULT_LABELS_TOPIC) -> Recording:
    """A labelled recording: scans on `topic` (the file's only LaserScan topic when None) and the legs of
    each scan from the geometry_msgs/PoseArray messages on `labels_topic` (laser frame, no header stamp:
    matched by log time, see match_labels). ROS 1 bags, ROS 2 bag folders and MCAP files.
    Raises InputError when the labels topic is missing or holds no leg at all."""
    from ...logs.importers.rosbag import LASERSCAN_TYPES, choose_topic

    path = Path(path)
    chosen: list[str] = []

    def pick(topics: dict) -> list[str]:
        chosen.append(choose_topic(str(path), topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic"))
        return chosen

    raw = read_scans_and_poses(path, pick, labels_topic)
    if labels_topic not in raw.topics:
        raise InputError(
            f"{path}: no leg labels: no topic {labels_topic} (a labelled file needs "
            "geometry_msgs/PoseArray leg positions; choose the topic with --labels-topic)"
        )
    if raw.poses is None:
        raise InputError(f"{path}: {labels_topic} holds {raw.topics[labels_topic][0]}, not geometry_msgs/PoseArray")
    run, log_times = raw.runs[chosen[0]]
    legs = match_labels(log_times, *raw.poses)
    if not sum(len(x) for x in legs):
        raise InputError(
            f"{path}: no labelled leg on {labels_topic} within {LABEL_WINDOW_NS // 1_000_000} ms "
            f"of a scan on {chosen[0]}"
        )
    return Recording(f"{path.name}", path, chosen[0], run, legs)


def read_empty(path: str | Path, topic: str | None = None) -> list[Recording]:
    """Empty recordings (rooms with no people): one per LaserScan topic of the file, or `topic` alone."""
    from ...logs.importers.rosbag import LASERSCAN_TYPES, choose_topic

    path = Path(path)

    def pick(topics: dict) -> list[str]:
        if topic is not None:
            return [choose_topic(str(path), topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")]
        found = sorted(t for t, (m, n) in topics.items() if m in LASERSCAN_TYPES and n)
        if not found:
            others = ", ".join(f"{t} ({m})" for t, (m, _) in sorted(topics.items())) or "no topics"
            raise InputError(f"{path}: no sensor_msgs/LaserScan topic (it has {others})")
        return found

    raw = read_scans_and_poses(path, pick, None)
    several = len(raw.runs) > 1
    return [Recording(f"{path.name}:{t}" if several else path.name, path, t, run) for t, (run, _) in raw.runs.items()]
