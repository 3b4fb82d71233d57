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
  (the other laser messages carry their own pose). ``PARAM``, ``#`` comments and other upper-case messages
  (NEFF, SYNC, TRUEPOS, g2o's VERTEX_SE2 and EDGE_SE2, ...) are ignored; any other line, and a laser or
  ODOM line with the wrong number of fields or a non-number, is malformed: skipped and counted.

Conventions (stated in the README):

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
"""

from __future__ import annotations

import gzip
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import GeometryError, InputError
from ..scan import Odometry, ScanGeometry, ScanRun

FLASER_LIKE = ("FLASER", "RLASER")
RAWLASER = ("RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")
ROBOTLASER = ("ROBOTLASER1", "ROBOTLASER2")
LASER_MESSAGES = FLASER_LIKE + RAWLASER + ROBOTLASER
G2O_MESSAGES = ("VERTEX_SE2", "EDGE_SE2", "VERTEX_XY", "EDGE_SE2_XY")
_OTHER_KNOWN = ("ODOM", "PARAM", "NEFF", "SYNC", "TRUEPOS", "GPSNMEA", "SONAR", "BUMPER", "IMU")
_MESSAGE = re.compile(r"[A-Z][A-Z0-9_]*$")
SICK_CODE_M = 81.83        # SICK LMS cm mode: 8183..8191 are error / no-return codes
CARMEN_CAP_M = 50.0        # CARMEN logs cap no-return readings at (or just above) 50 m
MM_CODE_M = 32.767         # 0x7FFF mm
SYNTH_PERIOD_NS = 1_000_000_000


def sniff_text(head: bytes) -> str | None:
    """'carmen' or 'g2o' when the first bytes of a file look like such a text log, else None."""
    if b"\x00" in head:
        return None
    lines = head.decode("latin-1").splitlines()
    seen = set()
    for line in lines[:2000]:
        tok = line.split(None, 1)
        if tok and _MESSAGE.match(tok[0]):
            seen.add(tok[0])
    if seen & set(G2O_MESSAGES):
        return "g2o"
    if seen & set(LASER_MESSAGES + _OTHER_KNOWN):
        return "carmen"
    return None


@dataclass
class _Stream:
    """The scans of one laser message, as parsed (before geometry and stamps are settled)."""

    name: str
    ranges: list = field(default_factory=list)        # arrays (n,), metres
    remissions: list = field(default_factory=list)    # arrays (n,) or (0,)
    stamps_s: list = field(default_factory=list)      # ipc_timestamp, seconds
    poses: list = field(default_factory=list)         # (x, y, theta) of the laser, world frame
    geometry: tuple | None = None                     # (start, resolution, max_range) or None (FLASER)
    n_beams: int = 0
    first_line: int = 0


@dataclass
class CarmenParse:
    """Everything `parse_lines` kept: laser streams by message name, ODOM poses, PARAMs, malformed lines."""

    streams: dict[str, _Stream] = field(default_factory=dict)
    odom: list = field(default_factory=list)          # (stamp_s, x, y, theta)
    params: dict[str, str] = field(default_factory=dict)
    malformed: int = 0
    malformed_lines: list[int] = field(default_factory=list)
    lines: int = 0
    counts: dict[str, int] = field(default_factory=dict)


class _Malformed(ValueError):
    pass


def _laser_fields(tok: list[str], robot: bool) -> tuple[tuple, np.ndarray, np.ndarray, float, tuple | None]:
    """(geometry, ranges, remissions, ipc_s, laser pose) of a RAWLASER/ROBOTLASER line."""
    head = np.array(tok[2:6], float)  # start, fov, resolution, max_range
    n = int(tok[8])
    if n < 1 or len(tok) < 10 + n:
        raise _Malformed
    ranges = np.array(tok[9:9 + n], float)
    n_rem = int(tok[9 + n])
    rest = tok[10 + n + n_rem:]
    extra = 11 if robot else 0
    if n_rem < 0 or not (extra + 1 <= len(rest) <= extra + 3):
        raise _Malformed
    rem = np.array(tok[10 + n:10 + n + n_rem], float)
    nums = np.array(rest[:extra + 1], float)
    pose = tuple(nums[:3]) if robot else None
    return (float(head[0]), float(head[2]), float(head[3])), ranges, rem, float(nums[extra]), pose


def _flaser_fields(tok: list[str]) -> tuple[np.ndarray, float, tuple]:
    n = int(tok[1])
    if n < 1 or not (n + 9 <= len(tok) <= n + 11):
        raise _Malformed
    vals = np.array(tok[2:n + 9], float)
    return vals[:n], float(vals[n + 6]), tuple(vals[n:n + 3])


def parse_lines(lines: Iterable[str], *, topic: str | None = None, max_scans: int | None = None) -> CarmenParse:
    """Parse CARMEN text lines (pure: no files). Keeps at most `max_scans` scans per laser message and
    stops early once `topic`'s scans are complete. Raises GeometryError (without a file name) when a
    laser message changes its beam layout."""
    out = CarmenParse()
    streams = out.streams
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
                    s = streams[name] = _Stream(name, first_line=lineno)
                if max_scans is not None and len(s.ranges) >= max_scans:
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
                out.odom.append((v[6], v[0], v[1], v[2]))
            elif name == "PARAM" and len(tok) >= 3:
                out.params[tok[1]] = tok[2]
        except (_Malformed, ValueError, IndexError):
            out.counts[name] -= 1
            _bad(out, lineno)
    return out


def _bad(out: CarmenParse, lineno: int) -> None:
    out.malformed += 1
    if len(out.malformed_lines) < 3:
        out.malformed_lines.append(lineno)


def _add_scan(s: _Stream, lineno: int, ranges, rem, ipc, pose, geom) -> None:
    n = len(ranges)
    if not s.ranges:
        s.n_beams, s.geometry = n, geom
    elif n != s.n_beams or geom != s.geometry:
        was = f"{s.n_beams} beams" + (f", start/resolution/max {s.geometry}" if s.geometry else "")
        now = f"{n} beams" + (f", start/resolution/max {geom}" if geom else "")
        raise GeometryError(f"{s.name} geometry changes at scan {len(s.ranges)} (line {lineno}): "
                            f"{was} -> {now}; datmo does not split runs, cut the log at that line")
    s.ranges.append(ranges)
    s.remissions.append(rem if len(rem) == n else np.zeros(0))
    s.stamps_s.append(ipc)
    if pose is not None:
        s.poses.append(pose)


def flaser_angles(n_beams: int) -> tuple[float, float]:
    """(angle_min, angle_increment), radians, of a FLASER/RLASER scan of `n_beams` beams (module docstring)."""
    if n_beams < 2:
        return -np.pi / 2, np.pi
    if n_beams % 2 == 0:
        return -np.pi / 2, np.pi / n_beams
    return -np.pi / 2, np.pi / (n_beams - 1)


def no_return_limit(ranges: np.ndarray, stated_max: float | None = None) -> float:
    """The range (m) at or above which a reading means "no return" (see the module docstring)."""
    if stated_max is not None and stated_max > 0:
        return float(stated_max)
    top = float(np.nanmax(ranges)) if ranges.size else 0.0
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
    t = np.asarray(stamps_s, np.float64)
    ok = len(t) > 0 and bool(np.all(np.isfinite(t))) and t[0] >= 0
    bad = int(np.sum(np.diff(t) <= 0)) if ok else len(t)
    if ok and bad == 0:
        return np.round(t * 1e9).astype(np.int64), None
    if ok and bad <= 0.05 * len(t):
        ns = np.round(t * 1e9).astype(np.int64)
        for i in range(1, len(ns)):  # per scan, a few thousand at most
            if ns[i] <= ns[i - 1]:
                ns[i] = ns[i - 1] + 1_000_000
        return ns, f"{bad} stamps go backwards or repeat; each set 1 ms after the one before"
    t0 = float(t[0]) if len(t) and np.isfinite(t[0]) and t[0] >= 0 else 0.0
    synth = int(round(t0 * 1e9)) + np.arange(len(t), dtype=np.int64) * SYNTH_PERIOD_NS
    distinct = len(np.unique(t))
    return synth, f"not increasing ({distinct} distinct of {len(t)}); synthesised at 1 s per scan"


def pick_stream(parse: CarmenParse, topic: str | None, label: str) -> _Stream:
    """The laser stream to import: `topic`, or the only one. Raises InputError naming the choices."""
    names = [n for n in LASER_MESSAGES if n in parse.streams and parse.streams[n].ranges]
    listing = ", ".join(f"{n} ({parse.counts.get(n, 0)} scans)" for n in names)
    if topic is not None:
        if topic not in names:
            have = f"it has {listing}" if names else "it has no laser scans"
            raise InputError(f"{label}: no {topic} scans; {have}")
        return parse.streams[topic]
    if not names:
        skipped = f"; skipped {parse.malformed} malformed lines" if parse.malformed else ""
        raise InputError(f"{label}: no laser scans (no valid FLASER, RLASER, RAWLASER1-4 or ROBOTLASER1-2 "
                         f"lines{skipped})")
    if len(names) > 1:
        raise InputError(f"{label}: several laser streams, choose one with --topic: {listing}")
    return parse.streams[names[0]]


def build(parse: CarmenParse, topic: str | None = None, label: str = "<text>"):  # noqa: ANN201
    """(ScanRun, Odometry | None, warnings, facts) of a parsed log (pure)."""
    s = pick_stream(parse, topic, label)
    warnings: list[str] = []
    ranges = np.stack(s.ranges).astype(np.float64)
    n = s.n_beams
    if s.geometry is None:
        angle_min, inc = flaser_angles(n)
        limit = no_return_limit(ranges)
        if n not in (180, 181, 360, 361):
            warnings.append(f"{label}: {s.name} has {n} beams; assumed they span -90°..+90° inclusive")
        if parse.params.get("laser_front_laser_flipped", "off").lower() in ("1", "on", "yes", "true"):
            ranges = ranges[:, ::-1]
    else:
        angle_min, inc, stated = s.geometry
        limit = no_return_limit(ranges, stated)
    no_return = ranges >= limit
    ranges[no_return] = np.inf
    rem = None
    if all(len(r) == n for r in s.remissions):
        rem = np.stack(s.remissions)
    stamps, fixed = stamps_ns(np.array(s.stamps_s))
    synthesised = fixed is not None and fixed.endswith("per scan")
    if fixed:
        warnings.append(f"{label}: {s.name} timestamps: {fixed}")
    frame = "rear_laser" if s.name == "RLASER" else "laser"
    geometry = ScanGeometry(angle_min=float(angle_min), angle_increment=float(inc), n_beams=n,
                            range_min=0.0, range_max=float(limit), frame_id=frame)
    run = ScanRun(stamps, ranges.astype(np.float32), geometry, rem)
    odom, odom_source = _odometry(parse, s, stamps, synthesised, frame, label, warnings)
    if parse.malformed:
        where = ", ".join(str(i) for i in parse.malformed_lines)
        warnings.insert(0, f"{label}: skipped {parse.malformed} malformed line{'s' if parse.malformed != 1 else ''}"
                           f" (first at line {where})")
    facts = {"message": s.name, "scans": len(run), "beams": n, "no_return_at_m": float(limit),
             "no_return_readings": int(no_return.sum()), "stamps": fixed or "ipc_timestamp",
             "malformed_lines": parse.malformed, "odometry_source": odom_source}
    return run, odom, warnings, facts


def _odometry(parse: CarmenParse, s: _Stream, stamps: np.ndarray, synthesised: bool, frame: str, label: str,
              warnings: list[str]) -> tuple[Odometry | None, str | None]:
    if len(s.poses) == len(stamps):
        p = np.array(s.poses, np.float64)
        return Odometry(stamps.copy(), p[:, 0], p[:, 1], p[:, 2], frame_id="odom", child_frame_id=frame), s.name
    if not parse.odom:
        return None, None
    o = np.array(parse.odom, np.float64)
    o_ns, o_fixed = stamps_ns(o[:, 0])
    if synthesised or o_fixed:
        warnings.append(f"{label}: ODOM poses not written: their stamps cannot be matched to the scans")
        return None, None
    return Odometry(o_ns, o[:, 1], o[:, 2], o[:, 3]), "ODOM"


def _lines(f, progress, raw, total: int, label: str, warnings: list[str]):  # noqa: ANN001, ANN202
    """Lines of a text stream; reports progress by compressed bytes; a truncated gzip stream ends the lines
    with a warning instead of an error."""
    step = 0
    try:
        for line in f:
            step += 1
            if progress is not None and step % 20000 == 0:
                progress(raw.tell(), total)
            yield line
    except EOFError:
        warnings.append(f"{label}: gzip stream ends early (truncated file); read {step} lines before the cut")


def read_carmen(path: str | Path, *, topic: str | None = None, max_scans: int | None = None,
                progress=None):  # noqa: ANN001, ANN201
    """ImportResult of a CARMEN (or g2o ROBOTLASER1) text log, plain or gzipped."""
    from . import ImportResult

    path = Path(path)
    label = str(path)
    total = path.stat().st_size
    io_warnings: list[str] = []
    with open(path, "rb") as raw:
        gz = raw.read(2) == b"\x1f\x8b"
        raw.seek(0)
        binary = gzip.GzipFile(fileobj=raw) if gz else raw
        import io

        text = io.TextIOWrapper(binary, encoding="utf-8", errors="replace", newline=None)
        try:
            parse = parse_lines(_lines(text, progress, raw, total, label, io_warnings), topic=topic,
                                max_scans=max_scans)
        except GeometryError as exc:
            raise GeometryError(f"{label}: {exc}") from None
    if progress is not None:
        progress(total, total)
    if parse.lines == 0:
        raise InputError(f"{label}: empty file (no lines)")
    run, odom, warnings, facts = build(parse, topic, label)
    facts["params"] = {k: v for k, v in parse.params.items() if k.startswith(("laser_", "robot_front_laser"))}
    return ImportResult(run=run, odometry=odom, warnings=io_warnings + warnings, topic=facts["message"],
                        odom_topic=facts["odometry_source"], facts=facts)
