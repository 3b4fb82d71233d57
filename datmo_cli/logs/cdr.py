"""A numpy CDR codec for flat ROS 2 messages (little-endian XCDR1, as ROS 2 writes it).

"Flat" means what datmo_msgs use: a std_msgs/Header, numeric scalars, strings, fixed arrays and
sequences of numbers, and sequences of structs whose fields are all fixed-size. A struct sequence is
one numpy structured array, so encoding and decoding cost a few numpy calls per message, not a Python
call per element. Bytes are identical to rosbags' serializer (tests check it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from .types import fields as msg_fields

CDR_HEADER = b"\x00\x01\x00\x00"  # CDR, little endian
HEADER_TYPE = "std_msgs/msg/Header"
_NUMERIC = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "int64": "<i8",
    "uint64": "<u8",
    "float32": "<f4",
    "float64": "<f8",
}


def _align(pos: int, n: int) -> int:
    return (pos + n - 1) // n * n


@cache
def element_dtype(msgtype: str) -> np.dtype:
    """The numpy structured dtype whose bytes equal the CDR encoding of one `msgtype` element.

    Raises TypeError for types that are not fixed-size or whose CDR layout is not a C layout.
    """
    dtype, _ = _struct_layout(msgtype)
    return dtype


def _struct_layout(msgtype: str) -> tuple[np.dtype, int]:
    """(dtype, alignment) of a fixed-size struct laid out as CDR lays out consecutive elements."""
    fields = msg_fields(msgtype)
    names, formats, offsets = [], [], []
    pos, max_align = 0, 1
    for name, (node, spec) in fields:
        if node == 1:  # BASE
            base = spec[0]
            if base not in _NUMERIC:
                raise TypeError(f"{msgtype}.{name}: {base} is not fixed-size")
            fmt, size = np.dtype(_NUMERIC[base]), np.dtype(_NUMERIC[base]).itemsize
            align = size
        elif node == 2:  # NAME: nested struct
            fmt, align = _struct_layout(spec)
            size = fmt.itemsize
        elif node == 3:  # fixed ARRAY
            (inner_node, inner), count = spec
            if inner_node != 1 or inner[0] not in _NUMERIC:
                raise TypeError(f"{msgtype}.{name}: only arrays of numbers are supported")
            base = np.dtype(_NUMERIC[inner[0]])
            fmt, size, align = np.dtype((base, (count,))), base.itemsize * count, base.itemsize
        else:
            raise TypeError(f"{msgtype}.{name}: sequences and strings are not fixed-size")
        pos = _align(pos, align)
        names.append(name)
        formats.append(fmt)
        offsets.append(pos)
        pos += size
        max_align = max(max_align, align)
    first_align = formats[0].alignment if formats else 1
    if _align(pos, first_align) != _align(pos, max_align):
        raise TypeError(f"{msgtype}: CDR layout of consecutive elements is not a C layout; reorder fields")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": _align(pos, max_align)})
    return dtype, max_align


@dataclass(frozen=True)
class _Field:
    name: str
    kind: str  # header | scalar | string | array | seq | structseq
    dtype: np.dtype | None = None
    align: int = 1
    count: int = 0


@cache
def _plan(msgtype: str) -> tuple[_Field, ...]:
    fields = msg_fields(msgtype)
    plan = []
    for name, (node, spec) in fields:
        if node == 2 and spec == HEADER_TYPE:
            plan.append(_Field(name, "header"))
        elif node == 1 and spec[0] == "string":
            plan.append(_Field(name, "string"))
        elif node == 1:
            dt = np.dtype(_NUMERIC[spec[0]])
            plan.append(_Field(name, "scalar", dt, dt.itemsize))
        elif node == 3:
            (inner_node, inner), count = spec
            dt = np.dtype(_NUMERIC[inner[0]])
            plan.append(_Field(name, "array", dt, dt.itemsize, count))
        elif node == 4:
            (inner_node, inner), _ = spec
            if inner_node == 1:
                dt = np.dtype(_NUMERIC[inner[0]])
                plan.append(_Field(name, "seq", dt, dt.itemsize))
            else:
                dt, align = _struct_layout(inner)
                plan.append(_Field(name, "structseq", dt, align))
        else:
            raise TypeError(f"{msgtype}.{name}: unsupported field for the flat codec")
    return tuple(plan)


def encode(msgtype: str, values: dict) -> bytes:
    """Encode a flat message to CDR bytes.

    `values` maps field names to values; the header is given as `stamp_ns` (int, nanoseconds) and
    `frame_id` (str). Sequences take numpy arrays (struct sequences: arrays of `element_dtype`).
    Missing fields are zero or empty.
    """
    parts = [CDR_HEADER]
    pos = 0

    def put(raw: bytes, align: int) -> None:
        nonlocal pos
        pad = (-pos) % align
        if pad:
            parts.append(b"\x00" * pad)
        parts.append(raw)
        pos += pad + len(raw)

    for f in _plan(msgtype):
        if f.kind == "header":
            stamp = int(values.get("stamp_ns", 0))
            put(np.array([stamp // 1_000_000_000, stamp % 1_000_000_000], "<i4").tobytes(), 4)
            _put_string(put, values.get("frame_id", ""))
        elif f.kind == "string":
            _put_string(put, values.get(f.name, ""))
        elif f.kind == "scalar":
            put(np.asarray(values.get(f.name, 0), f.dtype).tobytes(), f.align)
        elif f.kind == "array":
            arr = np.zeros(f.count, f.dtype) if f.name not in values else np.asarray(values[f.name], f.dtype)
            if arr.shape != (f.count,):
                raise ValueError(f"{msgtype}.{f.name} needs {f.count} values, got {arr.shape}")
            put(arr.tobytes(), f.align)
        else:
            dt = f.dtype
            arr = values.get(f.name)
            arr = np.zeros(0, dt) if arr is None else np.ascontiguousarray(arr, dt)
            put(len(arr).to_bytes(4, "little"), 4)
            if len(arr):
                put(arr.tobytes(), f.align)
    return b"".join(parts)


def encode_block(msgtype: str, stamps_ns, frame_id: str, sequences: dict[str, tuple]) -> list[bytes]:
    """`encode` of one message per stamp, for message types made of a header and sequences only (as the
    datmo_msgs a stage writes per scan): every message's bytes are those `encode` gives, at a few Python
    operations per field instead of numpy calls. `sequences` maps each sequence field to (values, offsets):
    message k holds values[offsets[k]:offsets[k + 1]] (a numeric array, or a structured array of the field's
    element_dtype); fields left out are empty. TypeError for other message types."""
    plan = _plan(msgtype)
    if not plan or plan[0].kind != "header" or any(f.kind not in ("seq", "structseq") for f in plan[1:]):
        raise TypeError(f"{msgtype}: encode_block takes a header followed by sequences only")
    stamps = np.asarray(stamps_ns, np.int64)
    n = len(stamps)
    sec, nsec = np.divmod(stamps, 1_000_000_000)
    if n and (sec.min() < -(1 << 31) or sec.max() >= 1 << 31):
        raise OverflowError(f"{msgtype}: a stamp's seconds do not fit a CDR int32")
    head = np.stack([sec, nsec], axis=1).astype("<i4").tobytes()
    fid = frame_id.encode() + b"\x00"
    fid = len(fid).to_bytes(4, "little") + fid
    start = 8 + len(fid)  # position after the header, from the end of the 4-byte CDR header
    fields = []
    for f in plan[1:]:
        values, offsets = sequences.get(f.name, (np.zeros(0, f.dtype), np.zeros(n + 1, np.int64)))
        values = np.ascontiguousarray(values, f.dtype)
        offsets = np.asarray(offsets, np.int64)
        if len(offsets) != n + 1:
            raise ValueError(f"{msgtype}.{f.name}: {len(offsets)} offsets for {n} messages")
        size = f.dtype.itemsize
        fields.append((values.tobytes(), (offsets * size).tolist(), np.diff(offsets).tolist(), f.align))
    zeros = b"\x00" * 8
    out = []
    for k in range(n):
        parts = [CDR_HEADER, head[8 * k : 8 * k + 8], fid]
        pos = start
        for raw, at, counts, align in fields:
            pad = -pos % 4
            count = counts[k]
            parts.append(zeros[:pad] + count.to_bytes(4, "little"))
            pos += pad + 4
            if count:
                pad = -pos % align
                a, b = at[k], at[k + 1]
                parts.append(zeros[:pad] + raw[a:b])
                pos += pad + b - a
        out.append(b"".join(parts))
    return out


def _put_string(put, text: str) -> None:
    raw = text.encode() + b"\x00"
    put(len(raw).to_bytes(4, "little") + raw, 4)


class DecodeError(ValueError):
    """A payload that is not a `msgtype` message: a length runs past its end, bytes follow its last field, a
    string is not UTF-8, it is not little-endian CDR. The message says which (callers add the file and topic)."""


def decode_many(msgtype: str, payloads: list, first: int = 0) -> list[dict]:
    """`decode` of each payload; a DecodeError names the message (counted from `first`)."""
    out = []
    for i, p in enumerate(payloads):
        try:
            out.append(decode(msgtype, p))
        except DecodeError as exc:
            raise DecodeError(f"message {first + i}: {exc}") from None
    return out


def decode(msgtype: str, data: bytes | memoryview) -> dict:
    """Decode CDR bytes of a flat message into a dict (the inverse of `encode`).

    Sequences come back as read-only numpy views into `data`. DecodeError when `data` is not such a message:
    every length is checked against the payload's size (a damaged length is refused, never read past), and at
    most the 3 bytes of alignment padding may follow the last field.
    """
    if bytes(data[:2]) != CDR_HEADER[:2]:
        raise DecodeError(f"{msgtype}: not little-endian CDR data")
    buf = memoryview(data)[4:]
    try:
        out, pos = _decode(msgtype, buf)
    except (ValueError, IndexError, UnicodeDecodeError) as exc:  # numpy: a length past the end of the buffer
        raise DecodeError(f"{msgtype} of {len(buf) + 4} bytes: a length runs past its end ({exc})") from None
    if not 0 <= len(buf) - pos <= 3:
        raise DecodeError(f"{msgtype} of {len(buf) + 4} bytes: {len(buf) - pos} bytes after its last field")
    return out


def _decode(msgtype: str, buf: memoryview) -> tuple[dict, int]:
    out: dict = {}
    pos = 0
    for f in _plan(msgtype):
        if f.kind == "header":
            pos = _align(pos, 4)
            sec, nsec = np.frombuffer(buf, "<i4", 2, pos)
            out["stamp_ns"] = int(sec) * 1_000_000_000 + int(np.uint32(nsec))
            pos += 8
            out["frame_id"], pos = _get_string(buf, pos)
        elif f.kind == "string":
            out[f.name], pos = _get_string(buf, pos)
        elif f.kind == "scalar":
            pos = _align(pos, f.align)
            out[f.name] = np.frombuffer(buf, f.dtype, 1, pos)[0].item()
            pos += f.align
        elif f.kind == "array":
            pos = _align(pos, f.align)
            out[f.name] = np.frombuffer(buf, f.dtype, f.count, pos)
            pos += f.dtype.itemsize * f.count
        else:
            pos = _align(pos, 4)
            n = int.from_bytes(buf[pos : pos + 4], "little")
            pos += 4
            if n:
                pos = _align(pos, f.align)
            out[f.name] = np.frombuffer(buf, f.dtype, n, pos)
            pos += f.dtype.itemsize * n
    return out, pos


def _get_string(buf: memoryview, pos: int) -> tuple[str, int]:
    pos = _align(pos, 4)
    n = int.from_bytes(buf[pos : pos + 4], "little")
    if pos + 4 + n > len(buf):
        raise ValueError(f"a string of {n} bytes at byte {pos}")
    text = bytes(buf[pos + 4 : pos + 4 + n - 1]).decode() if n else ""
    return text, pos + 4 + n
