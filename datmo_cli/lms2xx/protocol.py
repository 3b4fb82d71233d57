"""The SICK LMS2xx serial protocol as pure functions: bytes in, frames and values out (no I/O).

Facts from docs/lms2xx.md (SICK's telegram listing, TL). A frame is
`STX addr len_lo len_hi command data... [status] crc_lo crc_hi`; the host sends address 00h, the LMS
replies with 80h and a status byte before the CRC. Words are little-endian. Distances are integers in mm
or cm; `values_to_ranges` turns them into metres (float32), overflow codes into NaN or +inf.
Times are in seconds unless a name says ns.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

STX, ACK, NAK = 0x02, 0x06, 0x15
HOST_ADDRESS, REPLY_ADDRESS = 0x00, 0x80
MAX_FRAME_LENGTH = 812  # largest Length field (command + data + status) an LMS sends (TL p.22)
MAX_FRAME_BYTES = MAX_FRAME_LENGTH + 6
PASSWORD = b"SICK_LMS"  # installation mode password (TL T7-12)
STATUS_OK = 0x10  # normal status byte: LMS type 6, no error (TL p.106)

BAUDS = (9600, 19200, 38400, 500000)
BAUD_CODES = {38400: 0x40, 19200: 0x41, 9600: 0x42, 500000: 0x48}  # 20h + code
CODE_BAUDS = {v: k for k, v in BAUD_CODES.items()}
STATUS_BAUD_WORDS = {500000: 0x8001, 38400: 0x8019, 19200: 0x8033, 9600: 0x8067}  # B1 bytes 116-117
STATUS_WORD_BAUDS = {v: k for k, v in STATUS_BAUD_WORDS.items()}

# Variants: (scan angle degrees, resolution in 1/100 degree) -> values per scan
VARIANTS = {(180, 100): 181, (180, 50): 361, (100, 100): 101, (100, 50): 201, (100, 25): 401}
RESOLUTIONS = {1.0: 100, 0.5: 50, 0.25: 25}  # degrees -> 1/100 degree
ROTATION_S = 0.01332  # one mirror turn, s (TL p.19)
ROTATIONS_PER_SCAN = {100: 1, 50: 2, 25: 4}  # interlaced rotations per complete scan
# Scans lost per scan sent, by resolution (1/100 degree) and baud (TL T10-17, best case)
LOST_PER_SENT = {
    100: {9600: 30, 19200: 15, 38400: 8, 500000: 0},
    50: {9600: 29, 19200: 15, 38400: 8, 500000: 0},
    25: {9600: 16, 19200: 8, 38400: 4, 500000: 0},
}

# Host commands (first payload byte) and the LMS's reply codes
CMD_MODE, CMD_REQUEST, CMD_STATUS, CMD_ERRORS = 0x20, 0x30, 0x31, 0x32
CMD_VARIANT, CMD_READ_CONFIG, CMD_WRITE_CONFIG, CMD_RESET, CMD_TYPE = 0x3B, 0x74, 0x77, 0x10, 0x3A
MODE_INSTALLATION, MODE_STREAM, MODE_STOP, MODE_INTERLACED = 0x00, 0x24, 0x25, 0x2A
REPLY_MODE, REPLY_SCAN, REPLY_STATUS, REPLY_VARIANT = 0xA0, 0xB0, 0xB1, 0xBB
REPLY_READ_CONFIG, REPLY_WRITE_CONFIG, REPLY_INVALID = 0xF4, 0xF7, 0x92
REPLY_CODES = frozenset({0x90, 0x91, 0x92, 0xA0, 0xB0, 0xB1, 0xB2, 0xBA, 0xBB, 0xF4, 0xF7})

CONFIG_BYTES = 34  # 74h/77h configuration block (older firmware: 32)
STATUS_BYTES = 152  # B1 data after the reply code
# Distance bits by measuring mode (TL p.98); 0Fh: all 16 bits, no flags
DISTANCE_BITS = {0x00: 13, 0x01: 13, 0x02: 13, 0x03: 14, 0x04: 14, 0x05: 15, 0x06: 15, 0x0F: 16}
UNITS_M = {"mm": 0.001, "cm": 0.01}
INFO_UNITS = {0: "cm", 1: "mm"}
CONFIG_UNITS = {0: "cm", 1: "mm"}


class ProtocolError(ValueError):
    """Bytes that are not a valid LMS2xx frame or telegram."""


# ---------------------------------------------------------------------------------------------- CRC


def crc16(data: bytes | bytearray | memoryview) -> int:
    """SICK's CRC16 over `data` (STX through the status byte): one shift per byte, 16-bit byte window.

    Not CRC-16/ARC: crc16(bytes.fromhex("0200010031")) == 0x1215 (TL ch.9).
    """
    crc = 0
    prev = 0
    for b in data:
        if crc & 0x8000:
            crc = ((crc & 0x7FFF) << 1) ^ 0x8005
        else:
            crc <<= 1
        crc ^= (prev << 8) | b
        prev = b
    return crc


# --------------------------------------------------------------------------------------------- frames


@dataclass(frozen=True)
class Frame:
    """One telegram. `data` is what follows the command byte, without the status byte.

    status is None for host frames (address 00h). `start` is the stream offset of its STX (parser).
    """

    address: int
    command: int
    data: bytes
    status: int | None
    raw: bytes
    start: int = 0

    @property
    def is_reply(self) -> bool:
        return bool(self.address & 0x80)

    @property
    def payload(self) -> bytes:
        """Command byte and data (no status), as the protocol doc writes payloads."""
        return bytes([self.command]) + self.data


def build_frame(payload: bytes, *, address: int = HOST_ADDRESS, status: int | None = None) -> bytes:
    """The bytes of a frame carrying `payload` (command + data); a status byte is added for replies."""
    body = bytes(payload) + (b"" if status is None else bytes([status]))
    if not 1 <= len(body) <= MAX_FRAME_LENGTH:
        raise ProtocolError(f"frame length {len(body)} outside 1..{MAX_FRAME_LENGTH}")
    head = bytes([STX, address]) + struct.pack("<H", len(body))
    out = head + body
    return out + struct.pack("<H", crc16(out))


def host_frame(payload: bytes) -> bytes:
    """A host-to-LMS frame (address 00h, no status)."""
    return build_frame(payload, address=HOST_ADDRESS)


def reply_frame(payload: bytes, status: int = STATUS_OK) -> bytes:
    """An LMS-to-host frame (address 80h, with the status byte)."""
    return build_frame(payload, address=REPLY_ADDRESS, status=status)


def parse_frame(buf: bytes, start: int = 0) -> Frame:
    """Parse one complete frame (exactly Length + 6 bytes). Raises ProtocolError on STX, length or CRC."""
    buf = bytes(buf)
    if len(buf) < 7 or buf[0] != STX:
        raise ProtocolError("not a frame: no STX or too short")
    length = buf[2] | (buf[3] << 8)
    if length + 6 != len(buf):
        raise ProtocolError(f"length field {length} does not match {len(buf)} frame bytes")
    want = buf[-2] | (buf[-1] << 8)
    got = crc16(buf[:-2])
    if want != got:
        raise ProtocolError(f"CRC {want:04X} received, {got:04X} computed")
    reply = bool(buf[1] & 0x80)
    if reply and length < 2:
        raise ProtocolError("reply frame without a status byte")
    end = -3 if reply else -2
    return Frame(buf[1], buf[4], buf[5:end], buf[-3] if reply else None, buf, start)


# ------------------------------------------------------------------------------------------- commands


def cmd_status() -> bytes:
    """31h: request the status block (reply B1h)."""
    return host_frame(bytes([CMD_STATUS]))


def cmd_installation(password: bytes = PASSWORD) -> bytes:
    """20 00 + password: installation mode (needed before 77h)."""
    return host_frame(bytes([CMD_MODE, MODE_INSTALLATION]) + password)


def cmd_stream() -> bytes:
    """20 24: stream every complete scan."""
    return host_frame(bytes([CMD_MODE, MODE_STREAM]))


def cmd_interlaced() -> bytes:
    """20 2A: stream each mirror rotation's partial scan (interlaced)."""
    return host_frame(bytes([CMD_MODE, MODE_INTERLACED]))


def cmd_stop() -> bytes:
    """20 25: stop output (values on request)."""
    return host_frame(bytes([CMD_MODE, MODE_STOP]))


def cmd_baud(baud: int) -> bytes:
    """20 40/41/42/48: switch to 38400/19200/9600/500000 Bd (reply A0 at the old baud)."""
    if baud not in BAUD_CODES:
        raise ProtocolError(f"baud {baud} not supported (choose {', '.join(map(str, BAUDS))})")
    return host_frame(bytes([CMD_MODE, BAUD_CODES[baud]]))


def cmd_one_scan() -> bytes:
    """30 01: one scan on request."""
    return host_frame(bytes([CMD_REQUEST, 0x01]))


def cmd_variant(angle_deg: int, resolution_cdeg: int) -> bytes:
    """3Bh: scan angle (100 or 180 degrees) and resolution (25, 50 or 100 hundredths of a degree)."""
    if (angle_deg, resolution_cdeg) not in VARIANTS:
        raise ProtocolError(f"no variant {angle_deg}°/{resolution_cdeg / 100:g}°")
    return host_frame(bytes([CMD_VARIANT]) + struct.pack("<HH", angle_deg, resolution_cdeg))


def cmd_read_config() -> bytes:
    """74h: read the configuration block (reply F4h)."""
    return host_frame(bytes([CMD_READ_CONFIG]))


def cmd_write_config(block: bytes) -> bytes:
    """77h + block: write the configuration (one EEPROM cycle; installation mode first)."""
    return host_frame(bytes([CMD_WRITE_CONFIG]) + bytes(block))


# ------------------------------------------------------------------------------------- replies: data


@dataclass(frozen=True)
class Status:
    """Fields of the B1 status block (TL p.52-57)."""

    version: str
    operating_mode: int
    defective: int
    measuring_mode: int
    angle_deg: int
    resolution_cdeg: int
    baud: int | None
    keep_baud: bool
    units: str
    raw: bytes = field(repr=False, default=b"")

    def as_metadata(self) -> dict[str, str]:
        """String fields for a log's metadata record."""
        return {
            "version": self.version,
            "operating_mode": f"0x{self.operating_mode:02X}",
            "defective": str(self.defective),
            "measuring_mode": f"0x{self.measuring_mode:02X}",
            "angle_deg": str(self.angle_deg),
            "resolution_deg": f"{self.resolution_cdeg / 100:g}",
            "baud": str(self.baud),
            "keep_baud": str(self.keep_baud),
            "units": self.units,
            "raw_hex": self.raw.hex(),
        }


def _at(data: bytes, index: int) -> int:
    """B1 byte `index` (B1 itself is index 0)."""
    return data[index - 1]


def parse_status(data: bytes) -> Status:
    """The B1 block (data after the B1 code, without status byte: 152 bytes)."""
    if len(data) < 122:
        raise ProtocolError(f"status block of {len(data)} bytes, expected {STATUS_BYTES}")
    word = lambda i: _at(data, i) | (_at(data, i + 1) << 8)  # noqa: E731
    return Status(
        version=bytes(data[0:7]).decode("ascii", "replace").strip("\x00 "),
        operating_mode=_at(data, 8),
        defective=_at(data, 9),
        measuring_mode=_at(data, 102),
        angle_deg=word(107),
        resolution_cdeg=word(109),
        baud=STATUS_WORD_BAUDS.get(word(116)),
        keep_baud=bool(_at(data, 119)),
        units=CONFIG_UNITS.get(_at(data, 122), "reserved"),
        raw=bytes(data),
    )


def build_status(
    *,
    operating_mode: int = MODE_STOP,
    defective: int = 0,
    measuring_mode: int = 0,
    angle_deg: int = 180,
    resolution_cdeg: int = 50,
    baud: int = 9600,
    units: str = "mm",
    version: bytes = b"V02.30 ",
) -> bytes:
    """A B1 block (152 bytes) with the given fields, the rest zero (for the emulator)."""
    out = bytearray(STATUS_BYTES)
    out[0:7] = version[:7].ljust(7)

    def put(index: int, value: int) -> None:
        out[index - 1] = value

    put(8, operating_mode)
    put(9, defective)
    put(102, measuring_mode)
    struct.pack_into("<H", out, 106, angle_deg)
    struct.pack_into("<H", out, 108, resolution_cdeg)
    struct.pack_into("<H", out, 115, STATUS_BAUD_WORDS[baud])
    put(122, 1 if units == "mm" else 0)
    return bytes(out)


@dataclass(frozen=True)
class Config:
    """The fields of the 74h/77h configuration block that record uses (TL p.96-101)."""

    indices: bool  # availability bit 1: real-time indices in B0
    measuring_mode: int
    units: str
    raw: bytes


def parse_config(block: bytes) -> Config:
    """Fields of a configuration block (32 or 34 bytes)."""
    if len(block) < 7:
        raise ProtocolError(f"configuration block of {len(block)} bytes")
    return Config(bool(block[4] & 0x02), block[5], CONFIG_UNITS.get(block[6], "reserved"), bytes(block))


def with_config(block: bytes, *, units: str | None = None, indices: bool | None = None) -> bytes:
    """`block` with units and/or the real-time-indices bit changed; other bytes unchanged."""
    out = bytearray(block)
    if units is not None:
        out[6] = 1 if units == "mm" else 0
    if indices is not None:
        out[4] = (out[4] | 0x02) if indices else (out[4] & ~0x02 & 0xFF)
    return bytes(out)


DEFAULT_CONFIG = bytes([0x00, 0x00, 0x46, 0x00, 0x01, 0x00, 0x01]) + bytes(CONFIG_BYTES - 7)


# ---------------------------------------------------------------------------------------- B0 scans


@dataclass(frozen=True)
class Telegram:
    """A decoded B0 telegram: raw values (uint16, distance and flag bits) and the info word's fields.

    offset: partial-scan offset in quarter degrees (0-3, for .00/.25/.50/.75°); partial: an interlaced
    partial scan. scan_index/telegram_index: real-time indices (None when the LMS does not send them).
    """

    values: np.ndarray
    units: str
    partial: bool
    offset: int
    status: int
    scan_index: int | None = None
    telegram_index: int | None = None

    @property
    def count(self) -> int:
        return len(self.values)


def decode_b0(data: bytes, status: int = STATUS_OK) -> Telegram:
    """Decode B0 data (after the B0 code, without the status byte). Raises ProtocolError when the
    length disagrees with the info word's value count (indices are recognised by the 2 extra bytes)."""
    if len(data) < 2:
        raise ProtocolError("B0 telegram without an info word")
    info = data[0] | (data[1] << 8)
    n = info & 0x3FF
    extra = len(data) - 2 - 2 * n
    if extra not in (0, 2):
        raise ProtocolError(f"B0 with {n} values has {len(data)} data bytes (expected {2 * n + 2} or {2 * n + 4})")
    values = np.frombuffer(data, "<u2", n, 2).astype(np.uint16)
    unit_bits = info >> 14
    units = INFO_UNITS.get(unit_bits, "reserved")
    si = ti = None
    if extra:
        si, ti = data[2 + 2 * n], data[3 + 2 * n]
    return Telegram(values, units, bool(info & 0x2000), (info >> 11) & 0x3, status, si, ti)


def encode_b0(
    values: np.ndarray,
    units: str = "mm",
    *,
    partial: bool = False,
    offset: int = 0,
    indices: tuple[int, int] | None = None,
) -> bytes:
    """B0 payload (code, info word, values, optional indices) for `values` (uint16)."""
    v = np.ascontiguousarray(values, "<u2")
    if len(v) > 0x3FF:
        raise ProtocolError(f"{len(v)} values do not fit the info word")
    info = len(v) | ((offset & 3) << 11) | (0x2000 if partial else 0) | ((1 if units == "mm" else 0) << 14)
    out = bytes([REPLY_SCAN]) + struct.pack("<H", info) + v.tobytes()
    if indices is not None:
        out += bytes([indices[0] & 0xFF, indices[1] & 0xFF])
    return out


def b0_length(n_values: int, indices: bool = False) -> int:
    """The Length field of a B0 frame with `n_values` values."""
    return 2 * n_values + (6 if indices else 4)


def distance_bits(measuring_mode: int) -> int:
    """Distance bits of a measuring mode (13, 14, 15, or 16 for 0Fh). Raises ProtocolError for others."""
    try:
        return DISTANCE_BITS[measuring_mode]
    except KeyError:
        raise ProtocolError(f"measuring mode {measuring_mode:02X}h does not report distances") from None


def split_values(values: np.ndarray, measuring_mode: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(distances, flags) of raw values: distance bits and the flag bits above them (TL p.98)."""
    bits = distance_bits(measuring_mode)
    v = np.asarray(values, np.uint16)
    mask = np.uint16((1 << bits) - 1)
    return v & mask, (v >> np.uint16(bits % 16)) if bits < 16 else np.zeros_like(v)


def values_to_ranges(values: np.ndarray, units: str = "mm", measuring_mode: int = 0) -> np.ndarray:
    """Ranges in metres (float32) of raw values: masked distance x unit; ...F7 -> +inf, the other codes
    from ...F7 up (...FF invalid, ...FE dazzle, ...FD, ...FB, ...FA) -> NaN."""
    if units not in UNITS_M:
        raise ProtocolError(f"units {units!r} are reserved")
    dist, _ = split_values(values, measuring_mode)
    out = (dist.astype(np.float64) * UNITS_M[units]).astype(np.float32)
    bits = distance_bits(measuring_mode)
    if bits < 16:
        top = (1 << bits) - 9
        out[dist == top] = np.inf
        out[dist > top] = np.nan
    return out


def range_max_m(measuring_mode: int, units: str) -> float:
    """The mode's nominal reach in metres: 13 bits 8 m (mm) or 80 m (cm); 14 bits 16 m; 15 bits 32 m."""
    bits = distance_bits(measuring_mode)
    if units == "cm" and bits == 13:
        return 80.0
    return {13: 8.0, 14: 16.0, 15: 32.0, 16: 65.535}[bits]


def ranges_to_values(ranges: np.ndarray, units: str = "mm", measuring_mode: int = 0) -> np.ndarray:
    """Raw values for ranges (m): +inf -> ...F7, NaN -> ...FF, beyond reach -> ...F7 (for the emulator)."""
    bits = distance_bits(measuring_mode)
    top = (1 << bits) - 9 if bits < 16 else 0xFFFF
    r = np.asarray(ranges, np.float64)
    with np.errstate(invalid="ignore"):
        q = np.rint(r / UNITS_M[units])
        far = np.isposinf(r) | (q >= top)
        out = np.where(np.isfinite(q), np.clip(q, 0, top), 0).astype(np.uint16)
    out[far] = top
    out[np.isnan(r)] = (1 << bits) - 1 if bits < 16 else 0xFFFF
    return out


def scan_period_s(resolution_cdeg: int) -> float:
    """Time between complete scans in mode 24h: 13.32 ms x rotations per scan."""
    return ROTATION_S * ROTATIONS_PER_SCAN[resolution_cdeg]


def telegram_rate_hz(resolution_cdeg: int, baud: int) -> float:
    """Scans per second the LMS sends at a baud: base rate / (1 + scans lost per scan sent)."""
    return 1.0 / (scan_period_s(resolution_cdeg) * (1 + LOST_PER_SENT[resolution_cdeg][baud]))


def partial_count(angle_deg: int, resolution_cdeg: int, offset: int) -> int:
    """Values in an interlaced partial scan at quarter-degree `offset` (x.00° scans carry one more)."""
    return angle_deg + 1 if offset == 0 else angle_deg


def partial_positions(angle_deg: int, resolution_cdeg: int, offset: int) -> np.ndarray:
    """Indices into the complete scan (ascending angle) of a partial scan's values."""
    step = 100 // resolution_cdeg
    shift = offset * 25 // resolution_cdeg
    return np.arange(partial_count(angle_deg, resolution_cdeg, offset)) * step + shift


def partial_offsets(resolution_cdeg: int) -> tuple[int, ...]:
    """The quarter-degree offsets of the partial scans that make one complete scan, in sending order."""
    return {100: (0,), 50: (0, 2), 25: (0, 1, 2, 3)}[resolution_cdeg]
