"""Scans as arrays, and the LaserScan CDR codec that moves whole runs without per-beam Python.

A run is N scans of one geometry: stamps (int64 ns), ranges (N x B float32, metres, sensor frame,
beam i at angle_min + i * angle_increment radians, counter-clockwise from the sensor's x axis),
intensities (N x B float32, or N x 0 when the sensor gives none).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from datmo_cli.base import libm

from .cdr import CDR_HEADER


@dataclass(frozen=True)
class ScanGeometry:
    """The beam layout of a run. Angles in radians, ranges in metres, times in seconds."""

    angle_min: float
    angle_increment: float
    n_beams: int
    range_min: float
    range_max: float
    time_increment: float = 0.0
    scan_time: float = 0.0
    frame_id: str = "laser"

    @property
    def angle_max(self) -> float:
        """Angle of the last beam, radians (float32 arithmetic, as LaserScan stores it)."""
        return float(np.float32(self.angle_min) + np.float32(self.angle_increment) * np.float32(self.n_beams - 1))

    def angles(self) -> np.ndarray:
        """Beam angles, radians, float64, shape (n_beams,)."""
        return self.angle_min + self.angle_increment * np.arange(self.n_beams, dtype=np.float64)

    def same_beams(self, other: ScanGeometry) -> bool:
        """True when both put the same beams at the same angles with the same range limits."""
        f = np.float32
        return (
            self.n_beams == other.n_beams
            and f(self.angle_min) == f(other.angle_min)
            and f(self.angle_increment) == f(other.angle_increment)
            and f(self.range_min) == f(other.range_min)
            and f(self.range_max) == f(other.range_max)
            and self.frame_id == other.frame_id
        )

    def describe(self) -> str:
        return (
            f"{self.n_beams} beams from {np.degrees(self.angle_min):.2f}° by "
            f"{np.degrees(self.angle_increment):.3f}°, {self.range_min:g}-{self.range_max:g} m, "
            f"frame '{self.frame_id}'"
        )


@dataclass
class ScanRun:
    """A whole run of scans as arrays (see the module docstring for units and frames)."""

    stamps: np.ndarray  # (N,) int64, nanoseconds
    ranges: np.ndarray  # (N, B) float32, metres
    geometry: ScanGeometry
    intensities: np.ndarray = field(default=None)  # (N, B) or (N, 0) float32

    def __post_init__(self) -> None:
        self.stamps = np.ascontiguousarray(self.stamps, dtype=np.int64)
        self.ranges = np.ascontiguousarray(self.ranges, dtype=np.float32)
        if self.ranges.ndim != 2 or self.ranges.shape != (len(self.stamps), self.geometry.n_beams):
            raise ValueError(f"ranges must be ({len(self.stamps)}, {self.geometry.n_beams}), got {self.ranges.shape}")
        if self.intensities is None:
            self.intensities = np.zeros((len(self.stamps), 0), np.float32)
        self.intensities = np.ascontiguousarray(self.intensities, dtype=np.float32)
        if self.intensities.shape[0] != len(self.stamps) or self.intensities.shape[1] not in (0, self.geometry.n_beams):
            raise ValueError(f"intensities must be (N, B) or (N, 0), got {self.intensities.shape}")

    def __len__(self) -> int:
        return len(self.stamps)

    def slice(self, start: int, stop: int) -> ScanRun:
        return ScanRun(self.stamps[start:stop], self.ranges[start:stop], self.geometry, self.intensities[start:stop])


@dataclass
class Odometry:
    """Poses of the sensor's base in the world (odom) frame: x, y in metres, theta in radians."""

    stamps: np.ndarray  # (M,) int64 ns
    x: np.ndarray  # (M,) float64
    y: np.ndarray
    theta: np.ndarray
    frame_id: str = "odom"
    child_frame_id: str = "base_link"

    def __len__(self) -> int:
        return len(self.stamps)

    def at(self, stamps: np.ndarray) -> np.ndarray:
        """Poses (K x 3: x, y, theta) interpolated at `stamps` (ns); held constant past the ends."""
        t = np.asarray(stamps, np.int64)
        rel = (self.stamps - self.stamps[0]).astype(np.float64)
        q = (t - self.stamps[0]).astype(np.float64)
        x = np.interp(q, rel, self.x)
        y = np.interp(q, rel, self.y)
        th = np.interp(q, rel, np.unwrap(self.theta))
        return np.stack([x, y, libm.arctan2(libm.sin(th), libm.cos(th))], axis=1)


def _row_dtype(frame_len: int, n_beams: int, n_intens: int) -> np.dtype:
    """One LaserScan CDR payload (after the 4-byte encapsulation header) as a packed record."""
    pad = (-(12 + frame_len)) % 4
    fields = [
        ("sec", "<i4"),
        ("nanosec", "<u4"),
        ("frame_len", "<u4"),
        ("frame", f"V{frame_len + pad}"),
        ("angle_min", "<f4"),
        ("angle_max", "<f4"),
        ("angle_increment", "<f4"),
        ("time_increment", "<f4"),
        ("scan_time", "<f4"),
        ("range_min", "<f4"),
        ("range_max", "<f4"),
        ("n_ranges", "<u4"),
        ("ranges", "<f4", (n_beams,)),
        ("n_intens", "<u4"),
    ]
    if n_intens:
        fields.append(("intensities", "<f4", (n_intens,)))
    return np.dtype([("cdr", "V4")] + fields)


def encode_scans(run: ScanRun) -> list[bytes]:
    """CDR payloads of sensor_msgs/msg/LaserScan for every scan of `run` (bytes equal rosbags')."""
    g = run.geometry
    frame = g.frame_id.encode() + b"\x00"
    n_int = run.intensities.shape[1]
    dt = _row_dtype(len(frame), g.n_beams, n_int)
    rows = np.zeros(len(run), dt)
    rows["cdr"] = np.void(CDR_HEADER)
    rows["sec"] = run.stamps // 1_000_000_000
    rows["nanosec"] = run.stamps % 1_000_000_000
    rows["frame_len"] = len(frame)
    rows["frame"] = np.void(frame + b"\x00" * (dt["frame"].itemsize - len(frame)))
    for name in ("angle_min", "angle_increment", "time_increment", "scan_time", "range_min", "range_max"):
        rows[name] = getattr(g, name)
    rows["angle_max"] = g.angle_max
    rows["n_ranges"] = g.n_beams
    rows["ranges"] = run.ranges
    rows["n_intens"] = n_int
    if n_int:
        rows["intensities"] = run.intensities
    raw = rows.tobytes()
    size = dt.itemsize
    return [raw[i : i + size] for i in range(0, len(raw), size)]


def encode_scan(
    stamp_ns: int, ranges: np.ndarray, geometry: ScanGeometry, intensities: np.ndarray | None = None
) -> bytes:
    """CDR payload of one LaserScan."""
    inten = None if intensities is None else np.asarray(intensities, np.float32)[None]
    run = ScanRun(np.array([stamp_ns]), np.asarray(ranges, np.float32)[None], geometry, inten)
    return encode_scans(run)[0]


TELEGRAM = "std_msgs/msg/UInt8MultiArray"  # the message type of a scanner's raw telegrams (datmo record --raw)
_EMPTY_LAYOUT = struct.pack("<II", 0, 0)  # MultiArrayLayout: no dims, data_offset 0


def encode_telegram(raw: bytes) -> bytes:
    """CDR payload of a std_msgs/msg/UInt8MultiArray holding `raw` (a telegram's bytes) with an empty layout."""
    return CDR_HEADER + _EMPTY_LAYOUT + struct.pack("<I", len(raw)) + raw


def _geometry_of(rec: np.void | np.ndarray, frame_id: str, n_beams: int) -> ScanGeometry:
    return ScanGeometry(
        angle_min=float(rec["angle_min"]),
        angle_increment=float(rec["angle_increment"]),
        n_beams=n_beams,
        range_min=float(rec["range_min"]),
        range_max=float(rec["range_max"]),
        time_increment=float(rec["time_increment"]),
        scan_time=float(rec["scan_time"]),
        frame_id=frame_id,
    )


GEOMETRY_FIELDS = ("angle_min", "angle_increment", "angle_max", "range_min", "range_max")  # must be finite
_NS = 1_000_000_000


def decode_scan(data: bytes | memoryview) -> tuple[int, np.ndarray, np.ndarray, ScanGeometry]:
    """(stamp_ns, ranges, intensities, geometry) of one LaserScan CDR payload.

    Raises ValueError saying what is wrong for a payload whose length fields run past its end, whose header
    stamp is before 1970 or not a time (nanosec of 10^9 or more), or whose geometry is not finite."""
    buf = memoryview(data)
    if bytes(buf[:2]) != CDR_HEADER[:2]:
        raise ValueError("not little-endian CDR data")
    size = len(buf)
    if size < 16:
        raise ValueError(f"LaserScan payload of {size} bytes is too short for a header")
    frame_len = int.from_bytes(buf[12:16], "little")
    if 16 + frame_len + 36 > size:
        raise ValueError(f"frame_id length {frame_len} runs past the end of the {size}-byte message")
    p0 = 4 + 12 + frame_len
    p0 += (-(p0 - 4)) % 4
    n = int.from_bytes(buf[p0 + 28 : p0 + 32], "little")
    pi = p0 + 32 + 4 * n
    if pi + 4 > size:
        raise ValueError(f"{n} ranges run past the end of the {size}-byte message")
    ni = int.from_bytes(buf[pi : pi + 4], "little")
    if pi + 4 + 4 * ni > size:
        raise ValueError(f"{ni} intensities run past the end of the {size}-byte message")
    dt = _row_dtype(frame_len, n, ni)
    if size != dt.itemsize:
        raise ValueError(f"LaserScan payload of {size} bytes, expected {dt.itemsize}")
    rows = np.frombuffer(buf, dt, 1)
    _check_rows(rows, None)
    rec = rows[0]
    frame_id = bytes(buf[16 : 16 + max(frame_len - 1, 0)]).decode(errors="replace")
    stamp = int(rec["sec"]) * _NS + int(rec["nanosec"])
    inten = rec["intensities"].copy() if ni else np.zeros(0, np.float32)
    return stamp, rec["ranges"].copy(), inten, _geometry_of(rec, frame_id, n)


class GeometryChangeError(ValueError):
    """Scans of one topic change geometry mid-run."""


def stamp_problem(sec: int, nanosec: int) -> str | None:
    """What is wrong with a header stamp that is not a time after 1970 (sec < 0, nanosec of 10^9 or more)."""
    if sec < 0:
        return f"header stamp before 1970 (sec = {sec})"
    if nanosec >= _NS:
        return f"header stamp nanosec = {nanosec} is not below 10^9"
    return None


def geometry_problem(
    angle_min: float, angle_increment: float, n_beams: int, range_min: float, range_max: float
) -> str | None:
    """What is wrong with a finite scan geometry no scanner has (radians, metres), or None: a negative
    range_min, a range_max not above it (no reading could be a return), a zero angle step, or beams that
    span more than a turn."""
    import math

    if range_min < 0:
        return f"range_min is negative ({range_min:g} m)"
    if range_max <= range_min:
        return f"range_max {range_max:g} m is not above range_min {range_min:g} m"
    if n_beams > 1 and angle_increment == 0:
        return "angle_increment is 0"
    if abs(angle_increment) * (n_beams - 1) > 2 * math.pi * 1.001:
        return f"{n_beams} beams of {math.degrees(angle_increment):g}° span more than a turn"
    return None


def _check_rows(rows: np.ndarray, first: int | None) -> None:
    """Raise ValueError ("scan K: ...", K counted from `first`; no scan named when None) for the first of
    decoded LaserScan rows whose header stamp is before 1970 or not a time, or whose geometry is not finite
    or not a scanner's (geometry_problem)."""
    bad = np.flatnonzero((rows["sec"] < 0) | (rows["nanosec"] >= _NS))
    if len(bad):
        r = rows[bad[0]]
        raise ValueError(_scan_label(first, bad[0]) + stamp_problem(int(r["sec"]), int(r["nanosec"])))
    for name in GEOMETRY_FIELDS:
        bad = np.flatnonzero(~np.isfinite(rows[name]))
        if len(bad):
            raise ValueError(f"{_scan_label(first, bad[0])}{name} is {float(rows[name][bad[0]])}")
    n = rows.dtype["ranges"].shape[0] if rows.dtype["ranges"].shape else 1
    step = np.abs(rows["angle_increment"].astype(np.float64))
    bad = np.flatnonzero(
        (rows["range_min"] < 0)
        | (rows["range_max"] <= rows["range_min"])
        | ((step == 0) & (n > 1))
        | (step * (n - 1) > 2 * np.pi * 1.001)
    )
    if len(bad):
        r = rows[bad[0]]
        raise ValueError(
            _scan_label(first, bad[0])
            + geometry_problem(
                float(r["angle_min"]), float(r["angle_increment"]), n, float(r["range_min"]), float(r["range_max"])
            )
        )


def _scan_label(first: int | None, i: int) -> str:
    return "" if first is None else f"scan {first + int(i)}: "


def decode_scans(payloads: list[bytes], first: int = 0) -> ScanRun:
    """Decode many LaserScan payloads into one ScanRun; errors name scans counted from `first` (the index of
    payloads[0] in its log).

    Fast path: when every payload has the same length and the same layout (frame id length, beam and
    intensity counts), the payloads are joined and viewed as one record array. Raises GeometryChangeError
    when the beam layout changes from one scan to the next, ValueError ("scan K: ...") for a scan that
    decode_scan refuses.
    """
    if not payloads:
        raise ValueError("no scans")
    first_payload = payloads[0]
    try:
        _, _, inten0, g0 = decode_scan(first_payload)
    except ValueError as exc:
        raise ValueError(f"scan {first}: {exc}") from None
    size = len(first_payload)
    if all(len(p) == size for p in payloads):
        frame_len = int.from_bytes(first_payload[12:16], "little")
        n_int = len(inten0)
        dt = _row_dtype(frame_len, g0.n_beams, n_int)
        rows = np.frombuffer(b"".join(payloads), dt)
        if all((rows[name] == rows[name][0]).all() for name in ("frame_len", "n_ranges", "n_intens")):
            _check_rows(rows, first)
            _check_constant(rows, g0, first)
            stamps = rows["sec"].astype(np.int64) * _NS + rows["nanosec"]
            inten = rows["intensities"] if n_int else np.zeros((len(rows), 0), np.float32)
            return ScanRun(stamps, rows["ranges"], g0, inten)
    stamps, ranges, intens = [], [], []
    for i, p in enumerate(payloads):
        try:
            s, r, it, g = decode_scan(p)
        except ValueError as exc:
            raise ValueError(f"scan {first + i}: {exc}") from None
        if not g.same_beams(g0):
            raise GeometryChangeError(f"scan geometry changes at scan {first + i}: {g0.describe()} -> {g.describe()}")
        stamps.append(s)
        ranges.append(r)
        intens.append(it)
    n_int = {len(it) for it in intens}
    if n_int == {g0.n_beams}:
        inten = np.stack(intens)
    elif n_int == {0}:
        inten = np.zeros((len(stamps), 0), np.float32)
    else:  # some scans carry intensities, some do not: NaN where missing
        inten = np.full((len(stamps), g0.n_beams), np.nan, np.float32)
        for i, it in enumerate(intens):
            if len(it) == g0.n_beams:
                inten[i] = it
    return ScanRun(np.array(stamps, np.int64), np.stack(ranges), g0, inten)


def _check_constant(rows: np.ndarray, g0: ScanGeometry, first: int = 0) -> None:
    for name in ("frame", "angle_min", "angle_increment", "range_min", "range_max"):
        col = rows[name]
        bad = np.flatnonzero(col != col[0])
        if len(bad):
            i = int(bad[0])
            frame_len = int(rows["frame_len"][i])
            frame_id = bytes(rows["frame"][i])[: max(frame_len - 1, 0)].decode(errors="replace")
            gi = _geometry_of(rows[i], frame_id, int(rows["n_ranges"][i]))
            raise GeometryChangeError(f"scan geometry changes at scan {first + i}: {g0.describe()} -> {gi.describe()}")
