"""CARMEN text logs (and g2o files with ROBOTLASER1 lines) into a ScanRun and Odometry.

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
  says they are SLAM-corrected (`pose_frame`: Radish's `*-corrected` logs). ``PARAM``, ``#`` comments and
  other upper-case messages (NEFF, SYNC, TRUEPOS, g2o's VERTEX_SE2 and EDGE_SE2, ...) are ignored; any other
  line, and a laser or ODOM line with the wrong number of fields or a non-number, or a RAWLASER/ROBOTLASER
  line whose beam fan cannot be a laser's (field of view or step zero, negative, NaN or over 360°), is
  malformed: skipped and counted. A line holding NUL bytes is malformed too; it does not make the file
  "binary"; so is a line longer than MAX_LINE characters, which is never held whole. A pose (the laser lines'
  or ODOM's x, y, theta) that is NaN or infinite is left out of /odom with a warning (its scan is kept): one
  such pose would make every track's world position NaN.

Conventions (stated in docs/import.md):

- Beam angles (radians, counter-clockwise from the laser's x axis): RAWLASER/ROBOTLASER give start angle
  and resolution. FLASER/RLASER with n = 181 or 361 (or any odd n) beams span -90°..+90° inclusive; with
  n = 180 or 360 (any even n) they follow CARMEN's convention for those sensors: beam i at
  -90° + i·180°/n, so 1° or 0.5° steps from -90° to +89° or +89.5°. ``PARAM laser_front_laser_flipped``
  on reverses the beam order.
- No return: a reading at or above the sensor's maximum becomes +inf (REP 117) and range_max is that
  maximum. RAWLASER/ROBOTLASER state it (max_range). For FLASER/RLASER it is taken from the file's
  no-return codes: 81.83 m when readings reach SICK's 8183-8191 cm error codes, else 50 m when readings
  reach CARMEN's 50 m cap (values such as 51.15 m), else 32.767 m (0x7FFF mm) when that code occurs,
  else 81.83 m (nothing is marked). ``PARAM robot_front_laser_max`` is not trusted (edmonton says 10 m
  and holds 51 m readings).
- Stamps: ipc_timestamp seconds -> int64 ns. When up to 5 % of them go backwards or repeat (intel), each
  such stamp is set 1 ms after the one before; when more do (several logs print them with 6 significant
  digits, or as 0), all are synthesised at 1 s per scan from the first stamp (0 when negative). Both warn.
  A stamp that is not finite, or beyond int64 nanoseconds (after 2262), counts as a stamp that cannot be
  kept: all are synthesised.

Streaming (`stream_carmen`): those rules need the whole log (its largest reading, its stamps, which laser
messages it holds), so one pass parses every line and spools the parsed scans to a temporary file, keeping
counts and a few numbers (StampCheck); the scans are then read back and written a block at a time, the
ODOM poses merged in time order. Memory does not grow with the log; the spool takes 8 bytes a reading.
"""

from __future__ import annotations

import gzip
import math
import re
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import DatmoError, GeometryError, InputError
from ..scan import Odometry, ScanGeometry, ScanRun

FLASER_LIKE = ("FLASER", "RLASER")
RAWLASER = ("RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")
ROBOTLASER = ("ROBOTLASER1", "ROBOTLASER2")
LASER_MESSAGES = FLASER_LIKE + RAWLASER + ROBOTLASER
G2O_MESSAGES = ("VERTEX_SE2", "EDGE_SE2", "VERTEX_XY", "EDGE_SE2_XY")
_OTHER_KNOWN = ("ODOM", "PARAM", "NEFF", "SYNC", "TRUEPOS", "GPSNMEA", "SONAR", "BUMPER", "IMU")
_MESSAGE = re.compile(r"[A-Z][A-Z0-9_]*$")
SICK_CODE_M = 81.83  # SICK LMS cm mode: 8183..8191 are error / no-return codes
CARMEN_CAP_M = 50.0  # CARMEN logs cap no-return readings at (or just above) 50 m
MM_CODE_M = 32.767  # 0x7FFF mm
SYNTH_PERIOD_NS = 1_000_000_000
MAX_STAMP_S = 9.2e9  # the largest stamp, seconds, that int64 nanoseconds hold (2^63 ns is 9.22e9 s)
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


class _Stream:
    """The scans of one laser message, as parsed (before geometry and stamps are settled): counts and
    whole-log figures, and the scans themselves either in lists (`parse_lines`) or spooled to a file
    (`spool` given: `read_carmen`, so memory holds no scan after it is parsed)."""

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
        with open(self._path, "rb") as f:
            for a in range(0, self.count, size):
                yield np.fromfile(f, np.float64, 4 * (min(self.count, a + size) - a)).reshape(-1, 4)


@dataclass
class CarmenParse:
    """Everything the parse kept: laser streams by message name, ODOM poses, PARAMs, malformed lines."""

    streams: dict[str, _Stream] = field(default_factory=dict)
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
    lines: Iterable[str], out: CarmenParse, streams: dict[str, _Stream], topic: str | None, max_scans: int | None
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
                    s = streams[name] = _Stream(name, first_line=lineno, spool=out.spool)
                if max_scans is not None and s.count >= max_scans:
                    if topic == name:
                        break
                    continue
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


def _add_scan(s: _Stream, lineno: int, ranges, rem, ipc, pose, geom) -> None:
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


def flaser_angles(n_beams: int) -> tuple[float, float]:
    """(angle_min, angle_increment), radians, of a FLASER/RLASER scan of `n_beams` beams (module docstring)."""
    if n_beams < 2:
        return -np.pi / 2, np.pi
    if n_beams % 2 == 0:
        return -np.pi / 2, np.pi / n_beams
    return -np.pi / 2, np.pi / (n_beams - 1)


def no_return_limit(ranges: np.ndarray, stated_max: float | None = None) -> float:
    """The range (m) at or above which a reading means "no return" (see the module docstring)."""
    top = float(np.nanmax(ranges)) if ranges.size else 0.0
    return _limit(top, stated_max)


def _limit(top: float, stated_max: float | None) -> float:
    """no_return_limit from the largest reading (`top`, NaN when there is none)."""
    if stated_max is not None and stated_max > 0:
        return float(stated_max)
    if top >= SICK_CODE_M - 1e-6:
        return SICK_CODE_M
    if top >= CARMEN_CAP_M:
        return CARMEN_CAP_M
    if abs(top - MM_CODE_M) < 1e-6:
        return MM_CODE_M
    return SICK_CODE_M


def stamps_ns(stamps_s: np.ndarray) -> tuple[np.ndarray, str | None]:
    """(int64 ns stamps, what was done to them or None) from ipc_timestamp seconds (module docstring).

    Increasing stamps are kept. When at most 5 % of the steps go backwards or repeat, each such stamp is
    set 1 ms after the one before ("repaired"); otherwise all are synthesised at 1 s per scan from the
    first stamp (0 when negative or not finite).
    """
    check = StampCheck()
    for t in np.asarray(stamps_s, np.float64).tolist():
        check.add(t)
    note = check.note(lambda: np.asarray(stamps_s, np.float64))
    return check.apply(np.asarray(stamps_s, np.float64)), note


class StampCheck:
    """`stamps_ns` over stamps that come one at a time: `add` each (seconds), then `note` what is done to
    them, then `apply` it to the same stamps block by block, in order. Holds a few numbers."""

    def __init__(self) -> None:
        self.n = 0
        self.ok = True  # every stamp finite and the first >= 0
        self.bad = 0  # steps that go backwards or repeat
        self._prev = 0.0
        self.t0 = 0.0
        self._done = 0  # stamps applied so far
        self._last_ns = 0

    def add(self, t: float) -> None:
        if self.n == 0:
            self.t0 = t
            self.ok = math.isfinite(t) and 0 <= t < MAX_STAMP_S
        elif not (math.isfinite(t) and t < MAX_STAMP_S):
            self.ok = False
        elif t - self._prev <= 0:
            self.bad += 1
        self._prev = t
        self.n += 1

    @property
    def mode(self) -> str:
        """ "keep", "repair" or "synthesise"."""
        if self.n and self.ok and self.bad == 0:
            return "keep"
        if self.n and self.ok and self.bad <= 0.05 * self.n:
            return "repair"
        return "synthesise"

    def note(self, stamps: Callable[[], np.ndarray]) -> str | None:
        """What is done to the stamps (None: kept); `stamps()` gives them all, for the count of distinct
        stamps of the synthesised case only."""
        mode = self.mode
        if mode == "keep":
            return None
        if mode == "repair":
            return f"{self.bad} stamps go backwards or repeat; each set 1 ms after the one before"
        distinct = len(np.unique(stamps()))
        return f"not increasing ({distinct} distinct of {self.n}); synthesised at 1 s per scan"

    def rewind(self) -> None:
        """Apply from the first stamp again."""
        self._done, self._last_ns = 0, 0

    def apply(self, t: np.ndarray) -> np.ndarray:
        """ns stamps of the next stamps `t` (s), carrying on from the block before."""
        t = np.asarray(t, np.float64)
        first, mode = self._done, self.mode
        self._done += len(t)
        if mode == "keep":
            return np.round(t * 1e9).astype(np.int64)
        if mode == "repair":
            ns = np.round(t * 1e9).astype(np.int64)
            last = self._last_ns
            for i in range(len(ns)):  # per scan, a few thousand at most
                if (first or i) and ns[i] <= last:
                    ns[i] = last + 1_000_000
                last = int(ns[i])
            self._last_ns = last
            return ns
        t0 = float(self.t0) if self.n and np.isfinite(self.t0) and 0 <= self.t0 < MAX_STAMP_S else 0.0
        return int(round(t0 * 1e9)) + np.arange(first, first + len(t), dtype=np.int64) * SYNTH_PERIOD_NS


def pick_stream(parse: CarmenParse, topic: str | None, label: str) -> _Stream:
    """The laser stream to import: `topic`, or the only one. Raises InputError naming the choices."""
    names = [n for n in LASER_MESSAGES if n in parse.streams and parse.streams[n].count]
    listing = ", ".join(f"{n} ({parse.counts.get(n, 0)} scans)" for n in names)
    if topic is not None:
        if topic not in names:
            have = f"it has {listing}" if names else "it has no laser scans"
            raise InputError(f"{label}: no {topic} scans; {have}")
        return parse.streams[topic]
    if not names:
        skipped = f"; skipped {parse.malformed} malformed lines" if parse.malformed else ""
        raise InputError(
            f"{label}: no laser scans (no valid FLASER, RLASER, RAWLASER1-4 or ROBOTLASER1-2 lines{skipped})"
        )
    if len(names) > 1:
        raise InputError(f"{label}: several laser streams, choose one with --topic: {listing}")
    return parse.streams[names[0]]


@dataclass
class _Plan:
    """How a parsed log's stream becomes scans and poses (what `build` settles from the whole log)."""

    stream: _Stream
    geometry: ScanGeometry
    limit: float
    flip: bool
    stamps_note: str | None
    odometry_source: str | None  # the laser message (its poses), "ODOM", or None
    warnings: list[str]
    facts: dict
    pose_frame: str = "odom"  # the poses' frame: "map" for SLAM-corrected poses (see pose_frame)


def pose_frame(label: str) -> str:
    """The frame of a log's poses: "map" when its file name says they are SLAM-corrected (Radish's
    `*-corrected` logs, whose FLASER x y theta, and odom_x odom_y odom_theta alike, come out of SLAM), else
    "odom" (raw odometry). The content cannot tell: a corrected log's two poses are the same numbers."""
    return "map" if "corrected" in Path(label).name.lower() else "odom"


def plan(parse: CarmenParse, topic: str | None = None, label: str = "<text>") -> _Plan:
    """Settle geometry, no-return limit, stamps and odometry of a parsed log (pure). Its facts'
    "no_return_readings" is counted as `blocks` gives the scans."""
    s = pick_stream(parse, topic, label)
    warnings: list[str] = []
    n = s.n_beams
    flip = False
    if s.geometry is None:
        angle_min, inc = flaser_angles(n)
        limit = _limit(s.top, None)
        if n not in (180, 181, 360, 361):
            warnings.append(f"{label}: {s.name} has {n} beams; assumed they span -90°..+90° inclusive")
        flip = parse.params.get("laser_front_laser_flipped", "off").lower() in ("1", "on", "yes", "true")
    else:
        angle_min, inc, stated = s.geometry
        limit = _limit(s.top, stated)
    fixed = s.stamps.note(s.all_stamps)
    synthesised = fixed is not None and fixed.endswith("per scan")
    if fixed:
        warnings.append(f"{label}: {s.name} timestamps: {fixed}")
    frame = "rear_laser" if s.name == "RLASER" else "laser"
    geometry = ScanGeometry(
        angle_min=float(angle_min),
        angle_increment=float(inc),
        n_beams=n,
        range_min=0.0,
        range_max=float(limit),
        frame_id=frame,
    )
    odom = parse.odom
    if s.posed == s.count:  # the laser lines carry the poses
        odom_source = s.name if s.unposed.count < s.count else None
        if s.unposed.count:
            warnings.append(s.unposed.said(label, s.name, s.count))
    elif not len(odom):
        odom_source = None
    elif odom.unposed.count == odom.count:
        warnings.append(odom.unposed.said(label, "ODOM", odom.count))
        odom_source = None
    elif synthesised or odom.stamps.mode != "keep":
        warnings.append(f"{label}: ODOM poses not written: their stamps cannot be matched to the scans")
        odom_source = None
    else:
        odom_source = "ODOM"
        if odom.unposed.count:
            warnings.append(odom.unposed.said(label, "ODOM", odom.count))
    if parse.malformed:
        where = ", ".join(str(i) for i in parse.malformed_lines)
        warnings.insert(
            0,
            f"{label}: skipped {parse.malformed} malformed line{'s' if parse.malformed != 1 else ''}"
            f" (first at line {where})",
        )
    facts = {
        "message": s.name,
        "scans": s.count,
        "beams": n,
        "no_return_at_m": float(limit),
        "no_return_readings": 0,
        "stamps": fixed or "ipc_timestamp",
        "malformed_lines": parse.malformed,
        "odometry_source": odom_source,
    }
    frame = pose_frame(label)
    if odom_source is not None:
        facts["pose_frame"] = frame
    return _Plan(s, geometry, limit, flip, fixed, odom_source, warnings, facts, frame)


def blocks(parse: CarmenParse, p: _Plan, size: int) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
    """The planned stream's scans and poses, `size` scans at a time, in time order (scans before poses of
    the same stamp): (scans, their laser poses) or, for ODOM poses, (scans, None) and (None, poses) pieces."""
    s = p.stream
    s.stamps.rewind()

    def scans() -> Iterator[tuple[ScanRun, Odometry | None]]:
        for ranges, rem, ipc, poses in s.blocks(size):
            if p.flip:
                ranges = ranges[:, ::-1]
            no_return = ranges >= p.limit
            ranges[no_return] = np.inf
            p.facts["no_return_readings"] += int(no_return.sum())
            stamps = s.stamps.apply(ipc)
            run = ScanRun(stamps, ranges.astype(np.float32), p.geometry, rem)
            odom = None
            if p.odometry_source == s.name:
                ok = np.isfinite(poses).all(axis=1)  # a pose that is not a number is left out (plan warns)
                odom = Odometry(
                    stamps[ok],
                    poses[ok, 0],
                    poses[ok, 1],
                    poses[ok, 2],
                    frame_id=p.pose_frame,
                    child_frame_id=p.geometry.frame_id,
                )
            yield run, odom

    if p.odometry_source != "ODOM":
        yield from scans()
        return
    check = parse.odom.stamps
    check.rewind()

    def poses() -> Iterator[Odometry]:
        for rows in parse.odom.blocks(size):
            stamps = check.apply(rows[:, 0])  # every row's, in order (a repair carries on from the one before)
            ok = np.isfinite(rows[:, 1:]).all(axis=1)
            yield Odometry(stamps[ok], rows[ok, 1], rows[ok, 2], rows[ok, 3], frame_id=p.pose_frame)

    yield from merge((run for run, _ in scans()), poses())


def merge(runs: Iterable[ScanRun], odoms: Iterable[Odometry]) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
    """Blocks of scans and of poses, each in time order, paired: each block of scans with the poses stamped
    up to its last scan, so every message of a pair comes before every message of the next (the writer
    orders a pair's messages)."""
    odoms = iter(odoms)
    pending: list[Odometry] = []
    more = True
    for run in runs:
        last = int(run.stamps[-1])
        while more and (not pending or int(pending[-1].stamps[-1]) <= last):
            nxt = next(odoms, None)
            if nxt is None:
                more = False
            elif len(nxt):
                pending.append(nxt)
        if not pending:
            yield run, None
            continue
        o = _cat(pending)
        m = int(np.searchsorted(o.stamps, last, side="right"))
        pending = [_cut(o, m, len(o))] if m < len(o) else []
        yield run, (_cut(o, 0, m) if m else None)
    for o in pending:
        yield None, o
    for o in odoms:
        if len(o):
            yield None, o


def _cut(o: Odometry, a: int, b: int) -> Odometry:
    return Odometry(o.stamps[a:b], o.x[a:b], o.y[a:b], o.theta[a:b], o.frame_id, o.child_frame_id)


def _cat(parts: list[Odometry]) -> Odometry:
    if len(parts) == 1:
        return parts[0]
    o = parts[0]
    return Odometry(
        *(np.concatenate([getattr(q, f) for q in parts]) for f in ("stamps", "x", "y", "theta")),
        o.frame_id,
        o.child_frame_id,
    )


def build(parse: CarmenParse, topic: str | None = None, label: str = "<text>"):
    """(ScanRun, Odometry | None, warnings, facts) of a parsed log, whole (pure)."""
    p = plan(parse, topic, label)
    runs, poses = [], []
    for run, odom in blocks(parse, p, max(p.stream.count, 1)):
        if run is not None:
            runs.append(run)
        if odom is not None:
            poses.append(odom)
    run = (
        runs[0]
        if len(runs) == 1
        else ScanRun(
            np.concatenate([r.stamps for r in runs]),
            np.concatenate([r.ranges for r in runs]),
            p.geometry,
            np.concatenate([r.intensities for r in runs]),
        )
    )
    return run, _cat(poses) if poses else None, p.warnings, p.facts


MAX_LINE = 1 << 20  # characters of a line: a laser line of 10,000 beams and remissions takes under 200,000
_TOO_LONG = "<a line longer than MAX_LINE>"  # what a longer line is read as: a malformed line (not a message name)


def _lines(f, progress, raw, total: int, label: str, warnings: list[str]):
    """Lines of a text stream, each read in at most MAX_LINE characters (a longer one, skipped in pieces of that
    size, comes out as _TOO_LONG: memory does not grow with a line's length, e.g. a gigabyte without a newline
    in a .log.gz); reports progress by compressed bytes; a truncated gzip stream ends the lines with a warning
    instead of an error."""
    step = 0
    try:
        while line := f.readline(MAX_LINE):
            step += 1
            if progress is not None and step % 20000 == 0:
                progress(raw.tell(), total)
            if len(line) == MAX_LINE and not line.endswith("\n"):
                while (rest := f.readline(MAX_LINE)) and not rest.endswith("\n"):
                    pass
                line = _TOO_LONG
            yield line
    except EOFError:
        warnings.append(f"{label}: gzip stream ends early (truncated file); read {step} lines before the cut")


def stream_carmen(
    path: str | Path,
    *,
    topic: str | None = None,
    max_scans: int | None = None,
    progress=None,
    spool_dir: str | Path | None = None,
    block_scans: int = 1024,
):
    """ImportStream of a CARMEN (or g2o ROBOTLASER1) text log, plain or gzipped.

    One pass parses the text and spools the scans to a temporary folder in `spool_dir` (the system's
    when None), keeping only counts and whole-log figures (no-return limit, stamp checks); the stream's
    blocks then read the spool `block_scans` scans at a time. Memory holds one block whatever the log's
    length (and, for a log whose stamps are synthesised, its stamps while counting the distinct ones).
    """
    import io
    import tempfile

    from . import ImportStream

    path = Path(path)
    label = str(path)
    total = path.stat().st_size
    io_warnings: list[str] = []
    try:
        spool = tempfile.TemporaryDirectory(prefix=".datmo-import-", dir=spool_dir)
    except OSError as exc:
        raise DatmoError(
            f"{spool_dir or tempfile.gettempdir()}: cannot make a temporary folder for the parsed "
            f"scans ({exc.strerror or exc})"
        ) from None
    try:
        with open(path, "rb") as raw:
            gz = raw.read(2) == b"\x1f\x8b"
            raw.seek(0)
            binary = gzip.GzipFile(fileobj=raw) if gz else raw
            text = io.TextIOWrapper(binary, encoding="utf-8", errors="replace", newline=None)
            try:
                parse = parse_lines(
                    _lines(text, progress, raw, total, label, io_warnings),
                    topic=topic,
                    max_scans=max_scans,
                    spool=Path(spool.name),
                )
            except GeometryError as exc:
                raise GeometryError(f"{label}: {exc}") from None
        if progress is not None:
            progress(total, total)
        if parse.lines == 0:
            raise InputError(f"{label}: empty file (no lines)")
        p = plan(parse, topic, label)
    except OSError as exc:  # the disk full while spooling, or the input unreadable
        spool.cleanup()
        raise DatmoError(
            f"{label}: {exc.strerror or exc} (reading it, or spooling its scans to {Path(spool.name).parent})"
        ) from None
    except BaseException:
        spool.cleanup()
        raise
    p.facts["params"] = {k: v for k, v in parse.params.items() if k.startswith(("laser_", "robot_front_laser"))}

    def pieces() -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        try:
            yield from blocks(parse, p, block_scans)
        finally:
            spool.cleanup()

    return ImportStream(
        pieces(),
        warnings=io_warnings + p.warnings,
        topic=p.stream.name,
        odom_topic=p.odometry_source,
        facts=p.facts,
        geometry=p.geometry,
        closer=spool.cleanup,
    )


def read_carmen(path: str | Path, *, topic: str | None = None, max_scans: int | None = None, progress=None):
    """ImportResult of a CARMEN (or g2o ROBOTLASER1) text log, plain or gzipped (the whole run)."""
    return stream_carmen(path, topic=topic, max_scans=max_scans, progress=progress).collect()
