"""Foxglove / RViz markers for tracks: visualization_msgs/msg/MarkerArray CDR bytes, written directly.

The bytes are written by log.markers. A scan's array holds few markers whatever the number of
tracks: DELETEALL, one SPHERE_LIST each for people and circle objects, one CUBE_LIST for rectangular and
unknown objects (tentative tracks faded), and for the confirmed tracks that move or are people (what a
viewer follows; most tracks are static clutter, drawn as dots only): one LINE_LIST of velocity arrows (1 s
ahead), one LINE_LIST of trajectory tails, and a TEXT_VIEW_FACING id label each. Positions in the tracking
frame named by `frame_id`.
"""

from __future__ import annotations

import numpy as np

from ..logs.markers import ADD, ARROW, CUBE_LIST, DELETEALL, LINE_LIST, SPHERE_LIST, MarkerArrayWriter, header
from ..logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
    STATUS_TENTATIVE,
)

NS = "datmo/tracks"
COLORS = {  # by class, RGBA
    CLASS_UNKNOWN: (0.6, 0.6, 0.6, 0.8),
    CLASS_PERSON: (0.1, 0.8, 0.2, 0.9),
    CLASS_CIRCLE_OBJECT: (0.9, 0.2, 0.2, 0.9),
    CLASS_RECTANGULAR_OBJECT: (0.2, 0.4, 0.9, 0.9),
}


_COLOR_TABLE = np.array([COLORS[k] for k in range(4)], np.float32)


def tail_segments(tail: np.ndarray, count: np.ndarray) -> np.ndarray:
    """LINE_LIST points (2 per segment, z = 0) joining consecutive positions of ring buffers `tail`
    (K, T, 2) that have had `count` (K,) positions written (the newest at index (count - 1) % T)."""
    K, T, _ = tail.shape
    if not K:
        return np.zeros((0, 3))
    n = np.minimum(count, T)
    j = np.arange(T)
    order = (count[:, None] - n[:, None] + j[None, :]) % T  # oldest first
    pts = tail[np.arange(K)[:, None], order]  # (K, T, 2)
    valid = j[None, :-1] < (n[:, None] - 1)  # segment j joins j and j + 1
    a, b = pts[:, :-1][valid], pts[:, 1:][valid]
    out = np.zeros((2 * len(a), 3))
    out[0::2, :2], out[1::2, :2] = a, b
    return out


def track_markers(
    stamp_ns: int,
    frame_id: str,
    tracks: np.ndarray,
    tail: np.ndarray | None = None,
    tail_count: np.ndarray | None = None,
    world: bool = False,
) -> bytes:
    """The MarkerArray CDR payload for one scan's tracks (Track elements). Positions are the tracks'
    world fields when `world`, else their sensor-frame fields; `tail` (K, T, 2) and `tail_count` (K,) are
    the tracks' ring buffers of recent positions in the same frame (see tail_segments; None: no tails)."""
    from . import _marker_kernels

    head = header(stamp_ns, frame_id, NS)
    f8 = np.float64
    px = tracks["world_x" if world else "x"].astype(f8)
    py = tracks["world_y" if world else "y"].astype(f8)
    vx = tracks["world_vx" if world else "vx"].astype(f8)
    vy = tracks["world_vy" if world else "vy"].astype(f8)
    shown = tracks["status"] != STATUS_TENTATIVE
    # what moves gets a velocity arrow, a tail and an id label; what stays put is a dot (clutter is most tracks)
    lively = shown & ((tracks["mobility"] == MOBILITY_DYNAMIC) | (tracks["classification"] == CLASS_PERSON))
    none = np.zeros(len(tracks), np.int64)
    pp, pc, cp, cc, op, oc, _, _ = _marker_kernels.marker_points(
        px,
        py,
        vx,
        vy,
        tracks["classification"].astype(np.int64),
        shown,
        0.3,
        _COLOR_TABLE,
        np.zeros((len(tracks), 1, 2)),
        none,
    )
    k = np.flatnonzero(lively)
    arrows = np.zeros((2 * len(k), 3))
    arrows[0::2, 0], arrows[0::2, 1] = px[k], py[k]
    arrows[1::2, 0], arrows[1::2, 1] = px[k] + vx[k], py[k] + vy[k]
    tails = tail_segments(tail[k], np.asarray(tail_count, np.int64)[k]) if tail is not None else np.zeros((0, 3))
    ids = tracks["id"].tolist()
    labels = k.tolist()
    w = MarkerArrayWriter(6 + len(labels), head)
    w.marker(0, ARROW, DELETEALL)
    w.marker(1, SPHERE_LIST, ADD, scale=(0.5, 0.5, 0.5), points=pp, colors=pc)
    w.marker(2, SPHERE_LIST, ADD, scale=(0.4, 0.4, 0.4), points=cp, colors=cc)
    w.marker(3, CUBE_LIST, ADD, scale=(0.3, 0.3, 0.3), points=op, colors=oc)
    w.marker(4, LINE_LIST, ADD, scale=(0.03, 0.0, 0.0), color=(1.0, 0.8, 0.0, 1.0), points=arrows)
    w.marker(5, LINE_LIST, ADD, scale=(0.02, 0.0, 0.0), color=(0.8, 0.8, 0.8, 0.7), points=tails)
    xs, ys = px.tolist(), py.tolist()
    for j in labels:
        w.text(100 + ids[j], str(ids[j]), xs[j], ys[j] + 0.4, z=0.5, height=0.3)
    return w.bytes()
