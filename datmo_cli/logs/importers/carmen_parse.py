"""Parsing CARMEN text logs (and g2o files with ROBOTLASER1 lines): lines in, laser streams and ODOM poses out,
spooled to files for a streaming import; geometry, limits and stamps are settled later (carmen_conventions.py).

Messages read (one per line, fields separated by white space):

- ``FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp``
  (``RLASER`` likewise, for the rear laser): ranges in metres over 180°, right to left; x, y, theta is the
  laser's (corrected) pose in the world frame, metres and radians.
- ``RAWLASER1..4 type start_angle fov resolution max_range accuracy remission_mode n r1..rn
  n_rem rem1..rem_nrem ipc_timestamp hostname logger_timestamp``: angles in radians.
- ``ROBOTLASER1..2``: as RAWLASER, then ``laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
  forward_safety side_safety turn_axis`` before the timestamps.
- ``ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp``: used for /odom only with RAWLASER
  (the other laser messages carry their own pose). Poses are in frame "odom", or "map" when the file name
  says they are SLAM-corrected (carmen.pose_frame: Radish's `*-corrected` logs). ``PARAM``, ``#`` comments and
  other upper-case messages (NEFF, SYNC, TRUEPOS, g2o's VERTEX_SE2 and EDGE_SE2, ...) are ignored; any other
  line, and a laser or ODOM line with the wrong number of fields or a non-number, or a RAWLASER/ROBOTLASER
  line whose beam fan cannot be a laser's (field of view or step zero, negative, NaN or over 360°), is
  malformed: skipped and counted. A line holding NUL bytes is malformed too; it does not make the file
  "binary"; so is a line longer than carmen.MAX_LINE characters, which is never held whole. A pose (the laser lines'
  or ODOM's x, y, theta) that is NaN or infinite is left out of /odom with a warning (its scan is kept): one
  such pose would make every track's world position NaN.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...base.errors import GeometryError
from .carmen_conventions import StampCheck

FLASER_LIKE = ("FLASER", "RLASER")
RAWLASER = ("RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")
ROBOTLASER = ("ROBOTLASER1", "ROBOTLASER2")
LASER_MESSAGES = FLASER_LIKE + RAWLASER + ROBOTLASER
G2O_MESSAGES = ("VERTEX_SE2", "EDGE_SE2", "VERTEX_XY", "EDGE_SE2_XY")
_OTHER_KNOWN = ("ODOM", "PARAM", "NEFF", "SYNC", "TRUEPOS", "GPSNMEA", "SONAR", "BUMPER", "IMU")
_MESSAGE = re.compile(r"[A-Z][A-Z0-9_]*$")
_META = struct.Struct("<4d")  # spooled per scan: ipc stamp, laser pose (NaN when none); per ODOM line: a row


def sniff_text(head: bytes) -> str | None:
    """'carmen' or 'g2o' when the first bytes of a file look like such a text log, else None."""
    lines = head.decode("latin-1").splitlines()
    seen = set()
    for line in lines[:2000]:
        if "\x00" in line:  # a block of NULs (a crash, a copy cut short) is a malformed line, not a binary file
            continue
        tok = line.split(None, 1)
        if tok and _MESSAGE.match(tok[0]):
            seen.add(tok[0])
    if seen & set(G2O_MESSAGES):
        return "g2o"
    if seen & set(LASER_MESSAGES + _OTHER_KNOWN):
        return "carmen"
    return None


class LaserStream:
    """The scans of one laser message, as parsed (before geometry and stamps are settled): counts and
    whole-log figures, and the scans themselves either in lists (`parse_lines`) or spooled to a file
    (`spool` given: `stream_carmen`, so memory holds no scan after it is parsed)."""

    def __init__(self, name: str, first_line: int = 0, spool: Path | None = None) -> None:
        self.name = name
        self.first_line = first_line
        self.geometry: tuple | None = None  # (start, resolution, max_range) or None (FLASER)
        self.n_beams = 0
        self.count = 0
        self.top = np.nan  # largest reading (NaN ignored), for FLASER's no-return limit
        self.all_remissions = True  # every scan has one remission per beam
        self.posed = 0  # scans with a laser pose
        self.unposed = _NotANumber()  # of them, poses that are not finite numbers (left out of /odom)
        self.stamps = StampCheck()
        self.ranges: list = []  # (in memory) arrays (n,), metres
        self.remissions: list = []  # (in memory) arrays (n,) or (0,)
        self.stamps_s: list = []  # (in memory) ipc_timestamp, seconds
        self.poses: list = []  # (in memory) (x, y, theta) of the laser, world frame
        self._files = None
        if spool is not None:
            self._paths = tuple(spool / f"{name}.{part}" for part in ("ranges", "remissions", "meta"))
            self._files = tuple(open(p, "wb", buffering=1 << 20) for p in self._paths)

    def add(self, ranges: np.ndarray, rem: np.ndarray, ipc: float, pose: tuple | None) -> None:
        n = len(ranges)
        self.count += 1
        top = float(np.fmax.reduce(ranges))  # NaN readings ignored, as np.nanmax
        if top > self.top or self.top != self.top:
            self.top = top
        self.stamps.add(ipc)
        if pose is not None:
            self.posed += 1
        if self._files is None:
            self.ranges.append(ranges)
            self.remissions.append(rem if len(rem) == n else np.zeros(0))
            self.stamps_s.append(ipc)
            if pose is not None:
                self.poses.append(pose)
        else:
            f_ranges, f_rem, f_meta = self._files
            f_ranges.write(np.ascontiguousarray(ranges, np.float64).tobytes())
            if self.all_remissions and len(rem) == n:
                f_rem.write(np.ascontiguousarray(rem, np.float64).tobytes())
            f_meta.write(_META.pack(ipc, *(pose if pose is not None else (np.nan,) * 3)))
        if len(rem) != n:
            self.all_remissions = False

    def close(self) -> None:
        if self._files is not None:
            for f in self._files:
                f.close()

    def blocks(self, size: int) -> Iterator[tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]]:
        """(ranges (k, n) float64, remissions (k, n) or None, ipc stamps (k,) s, laser poses (k, 3)) of the
        scans in order, `size` at a time."""
        n = self.n_beams
        if self._files is None:
            for a in range(0, self.count, size):
                b = min(self.count, a + size)
                rem = np.stack(self.remissions[a:b]) if self.all_remissions else None
                poses = np.array(self.poses[a:b], np.float64).reshape(-1, 3) if self.posed else np.zeros((0, 3))
                stamps = np.array(self.stamps_s[a:b], np.float64)
                yield np.stack(self.ranges[a:b]).astype(np.float64), rem, stamps, poses
            return
        with open(self._paths[0], "rb") as fr, open(self._paths[1], "rb") as fm, open(self._paths[2], "rb") as fp:
            for a in range(0, self.count, size):
                k = min(self.count, a + size) - a
                ranges = np.fromfile(fr, np.float64, k * n).reshape(k, n)
                rem = np.fromfile(fm, np.float64, k * n).reshape(k, n) if self.all_remissions else None
                meta = np.fromfile(fp, np.float64, k * 4).reshape(k, 4)
                yield ranges, rem, meta[:, 0].copy(), meta[:, 1:].copy()

    def all_stamps(self) -> np.ndarray:
        """Every ipc stamp (s) of the stream; only for the warning of a log whose stamps are synthesised."""
        if self._files is None:
            return np.array(self.stamps_s, np.float64)
        return np.fromfile(self._paths[2], np.float64).reshape(-1, 4)[:, 0]


class _NotANumber:
    """Poses (x, y, theta) that are not finite numbers: how many, and the line of the first."""

    def __init__(self) -> None:
        self.count = 0
        self.first_line = 0

    def check(self, pose, lineno: int) -> None:
        if not all(math.isfinite(v) for v in pose):
            self.count += 1
            self.first_line = self.first_line or lineno

    def said(self, label: str, what: str, total: int) -> str:
        """The warning about them: which poses are left out of /odom (all: no /odom)."""
        which = "all" if self.count == total else f"{self.count} of the {total}"
        left = "no /odom written" if self.count == total else "left out of /odom"
        return (
            f"{label}: {which} {what} poses are not finite numbers (NaN or infinite; first at line "
            f"{self.first_line}); {left}"
        )


class _Odom:
    """ODOM poses (stamp_s, x, y, theta): in a list (`parse_lines`) or spooled to a file."""

    def __init__(self, spool: Path | None = None) -> None:
        self.rows: list = []
        self.count = 0
        self.stamps = StampCheck()
        self.unposed = _NotANumber()  # poses that are not finite numbers (left out of /odom)
        self._path = spool / "ODOM" if spool is not None else None
        self._file = open(self._path, "wb", buffering=1 << 20) if self._path is not None else None

    def append(self, row: tuple) -> None:
        self.count += 1
        self.stamps.add(row[0])
        if self._file is None:
            self.rows.append(row)
        else:
            self._file.write(_META.pack(*row))

    def close(self) -> None:
        if self._file is not None:
            self._file.close()

    def __len__(self) -> int:
        return self.count

    def blocks(self, size: int) -> Iterator[np.ndarray]:
        """Rows (k, 4) in order, `size` at a time."""
        if self._file is None:
            for a in range(0, self.count, size):
                yield np.array(self.rows[a : a + size], np.float64).reshape(-1, 4)
            return
        assert self._path is not None  # spooled: _file was opened at _path
        with open(self._path, "rb") as f:
            for a in range(0, self.count, size):
                yield np.fromfile(f, np.float64, 4 * (min(self.count, a + size) - a)).reshape(-1, 4)


@dataclass
class CarmenParse:
    """Everything the parse kept: laser streams by message name, ODOM poses, PARAMs, malformed lines."""

    streams: dict[str, LaserStream] = field(default_factory=dict)
    odom: _Odom = field(default_factory=_Odom)
    params: dict[str, str] = field(default_factory=dict)
    malformed: int = 0
    malformed_lines: list[int] = field(default_factory=list)
    lines: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    spool: Path | None = None  # where the scans are spooled (None: in memory)

    def close(self) -> None:
        for s in self.streams.values():
            s.close()
        self.odom.close()


class _Malformed(ValueError):
    pass


def _laser_fields(tok: list[str], robot: bool) -> tuple[tuple, np.ndarray, np.ndarray, float, tuple | None]:
    """(geometry, ranges, remissions, ipc_s, laser pose) of a RAWLASER/ROBOTLASER line."""
    start, fov, res, max_range = np.array(tok[2:6], float).tolist()
    n = int(tok[8])
    if n < 1 or len(tok) < 10 + n or not _sane_fan(start, fov, res, max_range):
        raise _Malformed
    ranges = np.array(tok[9 : 9 + n], float)
    n_rem = int(tok[9 + n])
    rest = tok[10 + n + n_rem :]
    extra = 11 if robot else 0
    if n_rem < 0 or not (extra + 1 <= len(rest) <= extra + 3):
        raise _Malformed
    rem = np.array(tok[10 + n : 10 + n + n_rem], float)
    nums = np.array(rest[: extra + 1], float)
    pose = tuple(nums[:3]) if robot else None
    return (start, res, max_range), ranges, rem, float(nums[extra]), pose


def _sane_fan(start: float, fov: float, res: float, max_range: float) -> bool:
    """Whether a RAWLASER/ROBOTLASER line's beam fan (radians) and stated maximum range (metres) can be a
    laser's: a finite start angle, a field of view in (0, 2π], a step in (0, fov], a finite maximum (zero
    or negative means "not stated"). A field of view of 0, or NaN, makes the line malformed, not a 0° step."""
    return (
        math.isfinite(start) and 0 < fov <= 2 * math.pi * 1.001 and 0 < res <= fov * 1.001 and math.isfinite(max_range)
    )


def _flaser_fields(tok: list[str]) -> tuple[np.ndarray, float, tuple]:
    n = int(tok[1])
    if n < 1 or not (n + 9 <= len(tok) <= n + 11):
        raise _Malformed
    vals = np.array(tok[2 : n + 9], float)
    return vals[:n], float(vals[n + 6]), tuple(vals[n : n + 3])


def parse_lines(
    lines: Iterable[str], *, topic: str | None = None, max_scans: int | None = None, spool: Path | None = None
) -> CarmenParse:
    """Parse CARMEN text lines (pure: no files unless `spool`, a folder to spool the scans to). Keeps at
    most `max_scans` scans per laser message and stops early once `topic`'s scans are complete. Raises
    GeometryError (without a file name) when a laser message changes its beam layout."""
    out = CarmenParse(odom=_Odom(spool), spool=spool)
    streams = out.streams
    try:
        _parse(lines, out, streams, topic, max_scans)
    finally:
        out.close()
    return out


def _parse(
    lines: Iterable[str], out: CarmenParse, streams: dict[str, LaserStream], topic: str | None, max_scans: int | None
) -> None:
    for lineno, line in enumerate(lines, 1):
        out.lines = lineno
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        name = tok[0]
        if not _MESSAGE.match(name):
            _bad(out, lineno)
            continue
        out.counts[name] = out.counts.get(name, 0) + 1
        try:
            if name in LASER_MESSAGES:
                s = streams.get(name)
                if s is None:
                    s = streams[name] = LaserStream(name, first_line=lineno, spool=out.spool)
                if max_scans is not None and s.count >= max_scans:
                    if topic == name:
                        break
                    continue
                geom: tuple | None
                pose: tuple | None
                if name in FLASER_LIKE:
                    ranges, ipc, pose = _flaser_fields(tok)
                    rem, geom = np.zeros(0), None
                else:
                    geom, ranges, rem, ipc, pose = _laser_fields(tok, robot=name in ROBOTLASER)
                _add_scan(s, lineno, ranges, rem, ipc, pose, geom)
            elif name == "ODOM":
                if len(tok) < 8:
                    raise _Malformed
                v = np.array(tok[1:8], float)
                out.odom.unposed.check(v[:3], lineno)
                out.odom.append((v[6], v[0], v[1], v[2]))
            elif name == "PARAM" and len(tok) >= 3:
                out.params[tok[1]] = tok[2]
        except (_Malformed, ValueError, IndexError):
            out.counts[name] -= 1
            _bad(out, lineno)


def _bad(out: CarmenParse, lineno: int) -> None:
    out.malformed += 1
    if len(out.malformed_lines) < 3:
        out.malformed_lines.append(lineno)


def _add_scan(s: LaserStream, lineno: int, ranges, rem, ipc, pose, geom) -> None:
    n = len(ranges)
    if not s.count:
        s.n_beams, s.geometry = n, geom
    elif n != s.n_beams or geom != s.geometry:
        was = f"{s.n_beams} beams" + (f", start/resolution/max {s.geometry}" if s.geometry else "")
        now = f"{n} beams" + (f", start/resolution/max {geom}" if geom else "")
        raise GeometryError(
            f"{s.name} geometry changes at scan {s.count} (line {lineno}): "
            f"{was} -> {now}; datmo does not split runs, cut the log at that line"
        )
    if pose is not None:
        s.unposed.check(pose, lineno)
    s.add(ranges, rem, ipc, pose)
