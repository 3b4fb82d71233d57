"""Foxglove / RViz markers for tracks: visualization_msgs/msg/MarkerArray CDR bytes, written directly.

Serialising a MarkerArray through rosbags costs far more than tracking a scan, so this module writes the
CDR bytes itself (tests check them against rosbags). A scan's array holds few markers whatever the number of
tracks: DELETEALL, one SPHERE_LIST each for people and circle objects, one CUBE_LIST for rectangular and
unknown objects (tentative tracks faded), and for the confirmed tracks that move or are people (what a
viewer follows; most tracks are static clutter, drawn as dots only): one LINE_LIST of velocity arrows (1 s
ahead), one LINE_LIST of trajectory tails, and a TEXT_VIEW_FACING id label each. Positions in the tracking
frame named by `frame_id`.
"""

from __future__ import annotations

import struct

import numpy as np

from ..log.cdr import CDR_HEADER

ARROW, CUBE, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST, CUBE_LIST, SPHERE_LIST = 0, 1, 2, 3, 4, 5, 6, 7
TEXT_VIEW_FACING = 9
ADD, DELETEALL = 0, 3
NS = "datmo/tracks"
COLORS = {  # by class code, RGBA
    0: (0.6, 0.6, 0.6, 0.8), 1: (0.1, 0.8, 0.2, 0.9), 2: (0.9, 0.2, 0.2, 0.9), 3: (0.2, 0.4, 0.9, 0.9)}
WHITE = (1.0, 1.0, 1.0, 1.0)
CLASS_PERSON, MOBILITY_DYNAMIC = 1, 1   # Track.msg's codes
_I3 = struct.Struct("<iii")
_POSE_SCALE = struct.Struct("<10d")
_COLOR_LIFE = struct.Struct("<4fiIB")


def _cstr(text: str) -> bytes:
    return text.encode() + b"\x00"


def _string(text: bytes) -> bytes:
    """A CDR string (length, bytes with the NUL) padded to 4 bytes: every field after it is 4-aligned."""
    raw = len(text).to_bytes(4, "little") + text
    return raw + b"\x00" * (-len(raw) % 4)


_EMPTY = _string(b"\x00")
# texture_resource, texture (stamp, frame_id, format, data), uv_coordinates: constant, and 4-aligned
_BEFORE_TEXT = _EMPTY + b"\x00" * 8 + _EMPTY + _EMPTY + b"\x00" * 8
# mesh_resource, mesh_file (filename, data), mesh_use_embedded_materials
_AFTER_TEXT = _EMPTY + _EMPTY + b"\x00" * 4 + b"\x00"
_NS = _string(_cstr(NS))


class _Writer:
    """Builds a MarkerArray payload; `pos` counts bytes after the 4-byte encapsulation header, which is
    what CDR alignment is relative to."""

    def __init__(self, count: int, head: bytes) -> None:
        self.parts: list[bytes] = [CDR_HEADER, count.to_bytes(4, "little")]
        self.pos = 4
        self.head = head   # stamp, frame_id and ns of every marker (4-aligned, 4-aligned length)

    def marker(self, mid: int, mtype: int, action: int, pose: tuple = (0.0, 0.0, 0.0),
               scale: tuple = (1.0, 1.0, 1.0), color: tuple = WHITE, points: np.ndarray | None = None,
               colors: np.ndarray | None = None, text: str = "") -> None:
        parts = self.parts
        pos = self.pos + (-self.pos % 4)   # a Marker starts 4-aligned (its header's stamp)
        if pos != self.pos:
            parts.append(b"\x00" * (pos - self.pos))
        parts.append(self.head)
        pos += len(self.head)
        # id, type, action, pose, scale, color, lifetime 0 (for ever), frame_locked false: cached bytes
        key = (mid, mtype, action, pose, scale, color, pos % 8)
        fixed = _FIXED.get(key)
        if fixed is None:
            pad = -(pos + 12) % 8
            raw = (_I3.pack(mid, mtype, action) + b"\x00" * pad
                   + _POSE_SCALE.pack(pose[0], pose[1], pose[2], 0.0, 0.0, 0.0, 1.0, *scale)
                   + _COLOR_LIFE.pack(*color, 0, 0, 0))
            fixed = raw + b"\x00" * (-(pos + len(raw)) % 4)
            if len(_FIXED) > 4096:
                _FIXED.clear()
            _FIXED[key] = fixed
        parts.append(fixed)
        pos += len(fixed)
        n = 0 if points is None else len(points)
        if n:
            pad = -(pos + 4) % 8
            raw = np.ascontiguousarray(points, "<f8").tobytes()
            parts.append(n.to_bytes(4, "little") + b"\x00" * pad + raw)
            pos += 4 + pad + len(raw)
        else:
            parts.append(b"\x00\x00\x00\x00")
            pos += 4
        n = 0 if colors is None else len(colors)
        if n:
            raw = np.ascontiguousarray(colors, "<f4").tobytes()
            parts.append(n.to_bytes(4, "little") + raw)
            pos += 4 + len(raw)
        else:
            parts.append(b"\x00\x00\x00\x00")
            pos += 4
        tail = _TAILS.get(text)
        if tail is None:
            text_raw = _cstr(text)
            tail = _BEFORE_TEXT + len(text_raw).to_bytes(4, "little") + text_raw
            tail += b"\x00" * (-len(tail) % 4) + _AFTER_TEXT
            if len(_TAILS) > 4096:
                _TAILS.clear()
            _TAILS[text] = tail
        parts.append(tail)
        self.pos = pos + len(tail)

    def label(self, track_id: int, x: float, y: float) -> None:
        """A TEXT_VIEW_FACING marker with the track id above (x, y): only the position changes from scan to
        scan, so the bytes around it are cached per id and alignment."""
        start = self.pos + (-self.pos % 4)
        key = (self.head, track_id, start % 8)
        cached = _LABELS.get(key)
        if cached is None:
            if len(_LABELS) > 4096:
                _LABELS.clear()
            probe = _Writer(0, self.head)
            probe.parts, probe.pos = [], start
            probe.marker(100 + track_id, TEXT_VIEW_FACING, ADD, pose=(0.0, 0.0, 0.5), scale=(0.0, 0.0, 0.3),
                         text=str(track_id))
            raw = b"".join(probe.parts)
            cut = len(self.head) + 12 + (-(start + len(self.head) + 12) % 8)   # where the pose begins
            cached = _LABELS[key] = (raw[:cut], raw[cut + 16:], len(raw))
        pre, post, n = cached
        if start != self.pos:
            self.parts.append(b"\x00" * (start - self.pos))
        self.parts.append(pre)
        self.parts.append(_XY.pack(x, y + 0.4))
        self.parts.append(post)
        self.pos = start + n

    def bytes(self) -> bytes:
        return b"".join(self.parts)


_LABELS: dict[tuple, tuple[bytes, bytes, int]] = {}
_FIXED: dict[tuple, bytes] = {}
_TAILS: dict[str, bytes] = {}
_XY = struct.Struct("<2d")


_COLOR_TABLE = np.array([COLORS[k] for k in range(4)], np.float32)


def tail_segments(tail: np.ndarray, count: np.ndarray) -> np.ndarray:
    """LINE_LIST points (2 per segment, z = 0) joining consecutive positions of ring buffers `tail`
    (K, T, 2) that have had `count` (K,) positions written (the newest at index (count - 1) % T)."""
    K, T, _ = tail.shape
    if not K:
        return np.zeros((0, 3))
    n = np.minimum(count, T)
    j = np.arange(T)
    order = (count[:, None] - n[:, None] + j[None, :]) % T          # oldest first
    pts = tail[np.arange(K)[:, None], order]                         # (K, T, 2)
    valid = j[None, :-1] < (n[:, None] - 1)                          # segment j joins j and j + 1
    a, b = pts[:, :-1][valid], pts[:, 1:][valid]
    out = np.zeros((2 * len(a), 3))
    out[0::2, :2], out[1::2, :2] = a, b
    return out


def track_markers(stamp_ns: int, frame_id: str, tracks: np.ndarray, tail: np.ndarray | None = None,
                  tail_count: np.ndarray | None = None, world: bool = False) -> bytes:
    """The MarkerArray CDR payload for one scan's tracks (Track elements). Positions are the tracks'
    world fields when `world`, else their sensor-frame fields; `tail` (K, T, 2) and `tail_count` (K,) are
    the tracks' ring buffers of recent positions in the same frame (see tail_segments; None: no tails)."""
    from . import _kernels

    head = (struct.pack("<iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000) + _string(_cstr(frame_id))
            + _NS)
    f8 = np.float64
    px = tracks["world_x" if world else "x"].astype(f8)
    py = tracks["world_y" if world else "y"].astype(f8)
    vx = tracks["world_vx" if world else "vx"].astype(f8)
    vy = tracks["world_vy" if world else "vy"].astype(f8)
    shown = tracks["status"] != 0
    # what moves gets a velocity arrow, a tail and an id label; what stays put is a dot (clutter is most tracks)
    lively = shown & ((tracks["mobility"] == MOBILITY_DYNAMIC) | (tracks["classification"] == CLASS_PERSON))
    none = np.zeros(len(tracks), np.int64)
    pp, pc, cp, cc, op, oc, _, _ = _kernels.marker_points(
        px, py, vx, vy, tracks["classification"].astype(np.int64), shown, 0.3, _COLOR_TABLE,
        np.zeros((len(tracks), 1, 2)), none)
    k = np.flatnonzero(lively)
    arrows = np.zeros((2 * len(k), 3))
    arrows[0::2, 0], arrows[0::2, 1] = px[k], py[k]
    arrows[1::2, 0], arrows[1::2, 1] = px[k] + vx[k], py[k] + vy[k]
    tails = (tail_segments(tail[k], np.asarray(tail_count, np.int64)[k]) if tail is not None
             else np.zeros((0, 3)))
    ids = tracks["id"].tolist()
    labels = k.tolist()
    w = _Writer(6 + len(labels), head)
    w.marker(0, ARROW, DELETEALL)
    w.marker(1, SPHERE_LIST, ADD, scale=(0.5, 0.5, 0.5), points=pp, colors=pc)
    w.marker(2, SPHERE_LIST, ADD, scale=(0.4, 0.4, 0.4), points=cp, colors=cc)
    w.marker(3, CUBE_LIST, ADD, scale=(0.3, 0.3, 0.3), points=op, colors=oc)
    w.marker(4, LINE_LIST, ADD, scale=(0.03, 0.0, 0.0), color=(1.0, 0.8, 0.0, 1.0), points=arrows)
    w.marker(5, LINE_LIST, ADD, scale=(0.02, 0.0, 0.0), color=(0.8, 0.8, 0.8, 0.7), points=tails)
    xs, ys = px.tolist(), py.tolist()
    for j in labels:
        w.label(ids[j], xs[j], ys[j])
    return w.bytes()
