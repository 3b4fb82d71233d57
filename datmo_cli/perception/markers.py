"""Foxglove / RViz markers for features: one visualization_msgs/msg/MarkerArray per scan.

Per scan: DELETEALL, a LINE_LIST of the lines (green), a LINE_LIST drawing every circle as an 8-sided
polygon (red), a SPHERE_LIST of blob centroids (orange), in the scan's sensor frame; and the landmark
database after the scan as a CUBE_LIST coloured by type, in the landmarks' frame (odom with odometry).
Bytes are written by log.markers (checked against rosbags in the tests).
"""

from __future__ import annotations

import numpy as np

from datmo_cli.base import libm

from ..logs.markers import ADD, ARROW, CUBE_LIST, DELETEALL, LINE_LIST, SPHERE_LIST, MarkerArrayWriter, header
from ..logs.scan import Odometry, ScanRun
from .features import RunFeatures

NS = "datmo/features"
LANDMARK_COLORS = np.array(
    [  # by landmark type: corner, convex, concave, line end, column, bench
        (0.0, 0.9, 0.9, 1.0),
        (0.6, 0.3, 0.9, 1.0),
        (0.9, 0.3, 0.6, 1.0),
        (0.7, 0.7, 0.7, 1.0),
        (1.0, 1.0, 0.0, 1.0),
        (0.6, 0.4, 0.2, 1.0),
    ],
    np.float32,
)
_POLY = 8  # sides of a circle drawn as a polygon: round enough at leg and column radii
_ANG = np.linspace(0.0, 2 * np.pi, _POLY + 1)


def line_points(lines: np.ndarray) -> np.ndarray:
    """LINE_LIST points (2 per line, z = 0) of Line elements."""
    out = np.zeros((2 * len(lines), 3))
    out[0::2, 0], out[0::2, 1] = lines["x_ini"], lines["y_ini"]
    out[1::2, 0], out[1::2, 1] = lines["x_end"], lines["y_end"]
    return out


def circle_points(circles: np.ndarray) -> np.ndarray:
    """LINE_LIST points drawing each Circle element as a polygon of _POLY sides."""
    if not len(circles):
        return np.zeros((0, 3))
    cx, cy, r = (circles[k].astype(np.float64)[:, None] for k in ("x", "y", "radius"))
    px, py = cx + r * libm.cos(_ANG), cy + r * libm.sin(_ANG)
    out = np.zeros((len(circles), _POLY, 2, 3))
    out[:, :, 0, 0], out[:, :, 0, 1] = px[:, :-1], py[:, :-1]
    out[:, :, 1, 0], out[:, :, 1, 1] = px[:, 1:], py[:, 1:]
    return out.reshape(-1, 3)


def feature_markers(run: ScanRun, f: RunFeatures, odometry: Odometry | None = None) -> list[bytes]:
    """MarkerArray CDR payloads, one per scan, for the features and landmarks of `f`."""
    lo, co, bo = f.line_offsets.tolist(), f.circle_offsets.tolist(), f.blob_offsets.tolist()
    lm = f.landmarks
    elems = lm.all_snapshots(f.stamps) if lm is not None else None
    lm_off = lm.snap_offsets.tolist() if lm is not None else None
    poses = odometry.at(f.stamps) if odometry is not None and len(odometry) else None
    return [
        scan_feature_markers(
            stamp,
            f.frame_id,
            f.lines[lo[k] : lo[k + 1]],
            f.circles[co[k] : co[k + 1]],
            f.blobs[bo[k] : bo[k + 1]],
            elems[lm_off[k] : lm_off[k + 1]] if elems is not None and lm_off is not None else None,
            poses[k] if poses is not None else None,
        )
        for k, stamp in enumerate(np.asarray(f.stamps, np.int64).tolist())
    ]


def scan_feature_markers(
    stamp: int,
    frame: str,
    lines: np.ndarray,
    circles: np.ndarray,
    blobs: np.ndarray,
    landmarks: np.ndarray | None = None,
    pose: np.ndarray | None = None,
) -> bytes:
    """The MarkerArray CDR payload of one scan: its Line, Circle and Blob elements (sensor frame `frame`) and
    the landmark database after it (Landmark elements; None: none drawn), brought into the sensor frame from
    the world frame by the scanner's `pose` (x, y, theta) when given. What feature_markers draws per scan, and
    what `datmo play` draws from a log's /datmo/features and /datmo/landmarks."""
    w = MarkerArrayWriter(5, header(stamp, frame, NS))
    w.marker(0, ARROW, DELETEALL)
    w.marker(1, LINE_LIST, ADD, scale=(0.04, 0.0, 0.0), color=(0.1, 0.9, 0.2, 1.0), points=line_points(lines))
    w.marker(2, LINE_LIST, ADD, scale=(0.02, 0.0, 0.0), color=(0.95, 0.2, 0.2, 1.0), points=circle_points(circles))
    pts = np.zeros((len(blobs), 3))
    pts[:, 0], pts[:, 1] = blobs["x"], blobs["y"]
    w.marker(3, SPHERE_LIST, ADD, scale=(0.08, 0.08, 0.08), color=(1.0, 0.6, 0.0, 1.0), points=pts)
    if landmarks is not None:
        e = landmarks
        pts = np.zeros((len(e), 3))
        pts[:, 0], pts[:, 1] = e["x"], e["y"]
        colors = LANDMARK_COLORS[e["type"].astype(np.int64)]
        if pose is not None and len(e):
            c, s = libm.cos(pose[2]), libm.sin(pose[2])
            dx, dy = pts[:, 0] - pose[0], pts[:, 1] - pose[1]
            pts[:, 0], pts[:, 1] = c * dx + s * dy, -s * dx + c * dy
        w.marker(4, CUBE_LIST, ADD, scale=(0.15, 0.15, 0.15), points=pts, colors=colors)
    else:
        w.marker(4, CUBE_LIST, ADD, scale=(0.15, 0.15, 0.15))
    return w.bytes()
