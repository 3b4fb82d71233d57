"""visualization_msgs/msg/MarkerArray CDR bytes, written directly (Foxglove / RViz markers).

Serialising a MarkerArray through rosbags costs far more than tracking a scan, so this module writes the
CDR bytes itself (tests check them against rosbags). `header` gives the stamp, frame_id and namespace every
marker of an array shares; a `MarkerArrayWriter` appends markers (`marker`, or `text` for a
TEXT_VIEW_FACING label) and gives the payload. What to draw is the caller's: tracking.markers and
perception.markers. Positions in metres, in the frame named in the header; colours RGBA in [0, 1].
"""

from __future__ import annotations

import struct

import numpy as np

from .cdr import CDR_HEADER

# visualization_msgs/msg/Marker's type and action codes
ARROW, CUBE, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST, CUBE_LIST, SPHERE_LIST = 0, 1, 2, 3, 4, 5, 6, 7
TEXT_VIEW_FACING = 9
ADD, DELETEALL = 0, 3
WHITE = (1.0, 1.0, 1.0, 1.0)
_I3 = struct.Struct("<iii")
_POSE_SCALE = struct.Struct("<10d")
_COLOR_LIFE = struct.Struct("<4fiIB")
_STAMP = struct.Struct("<iI")
_XY = struct.Struct("<2d")


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


def header(stamp_ns: int, frame_id: str, ns: str) -> bytes:
    """The bytes every marker of an array starts with: its header (stamp `stamp_ns` in ns, `frame_id`) and
    namespace `ns` (4-aligned, of 4-aligned length)."""
    return (
        _STAMP.pack(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000) + _string(_cstr(frame_id)) + _string(_cstr(ns))
    )


class MarkerArrayWriter:
    """Builds the CDR payload of a MarkerArray of `count` markers sharing `head` (see `header`); `pos`
    counts bytes after the 4-byte encapsulation header, which is what CDR alignment is relative to."""

    def __init__(self, count: int, head: bytes) -> None:
        self.parts: list[bytes] = [CDR_HEADER, count.to_bytes(4, "little")]
        self.pos = 4
        self.head = head

    def marker(
        self,
        mid: int,
        mtype: int,
        action: int,
        pose: tuple = (0.0, 0.0, 0.0),
        scale: tuple = (1.0, 1.0, 1.0),
        color: tuple = WHITE,
        points: np.ndarray | None = None,
        colors: np.ndarray | None = None,
        text: str = "",
    ) -> None:
        """Append marker `mid` of type `mtype` doing `action`: at position `pose` (m, no rotation), of
        `scale` (m), `color` (RGBA) or per-point `colors` (n, 4), with `points` (n, 3) m and `text`; lifetime 0
        (for ever), not frame-locked."""
        parts = self.parts
        pos = self.pos + (-self.pos % 4)  # a Marker starts 4-aligned (its header's stamp)
        if pos != self.pos:
            parts.append(b"\x00" * (pos - self.pos))
        parts.append(self.head)
        pos += len(self.head)
        # id, type, action, pose, scale, color, lifetime 0 (for ever), frame_locked false: cached bytes
        key = (mid, mtype, action, pose, scale, color, pos % 8)
        fixed = _FIXED.get(key)
        if fixed is None:
            pad = -(pos + 12) % 8
            raw = (
                _I3.pack(mid, mtype, action)
                + b"\x00" * pad
                + _POSE_SCALE.pack(pose[0], pose[1], pose[2], 0.0, 0.0, 0.0, 1.0, *scale)
                + _COLOR_LIFE.pack(*color, 0, 0, 0)
            )
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

    def text(self, mid: int, text: str, x: float, y: float, z: float, height: float) -> None:
        """Append marker `mid`: a TEXT_VIEW_FACING `text` of `height` m at (x, y, z) m. Only the position
        changes from scan to scan, so the bytes around it are cached per id, text and alignment."""
        start = self.pos + (-self.pos % 4)
        key = (self.head, mid, text, z, height, start % 8)
        cached = _LABELS.get(key)
        if cached is None:
            if len(_LABELS) > 4096:
                _LABELS.clear()
            probe = MarkerArrayWriter(0, self.head)
            probe.parts, probe.pos = [], start
            probe.marker(mid, TEXT_VIEW_FACING, ADD, pose=(0.0, 0.0, z), scale=(0.0, 0.0, height), text=text)
            raw = b"".join(probe.parts)
            cut = len(self.head) + 12 + (-(start + len(self.head) + 12) % 8)  # where the pose begins
            cached = _LABELS[key] = (raw[:cut], raw[cut + 16 :], len(raw))
        pre, post, n = cached
        if start != self.pos:
            self.parts.append(b"\x00" * (start - self.pos))
        self.parts.append(pre)
        self.parts.append(_XY.pack(x, y))
        self.parts.append(post)
        self.pos = start + n

    def bytes(self) -> bytes:
        """The MarkerArray payload, encapsulation header included."""
        return b"".join(self.parts)


_LABELS: dict[tuple, tuple[bytes, bytes, int]] = {}
_FIXED: dict[tuple, bytes] = {}
_TAILS: dict[str, bytes] = {}
