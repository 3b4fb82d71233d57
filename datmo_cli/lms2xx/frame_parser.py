"""Incremental parsing of an LMS2xx byte stream into frames (docs/lms2xx.md §2): chunks in as they arrive,
complete frames (and ACK/NAK bytes) out, resynchronising on garbage; pure, no I/O."""

from __future__ import annotations

from dataclasses import dataclass

from .protocol import (
    ACK,
    HOST_ADDRESS,
    MAX_FRAME_LENGTH,
    NAK,
    REPLY_ADDRESS,
    REPLY_CODES,
    REPLY_SCAN,
    STX,
    Frame,
    crc16,
)


@dataclass
class ParserStats:
    """What a FrameParser saw. resyncs: times it skipped bytes to find the next frame; discarded: bytes
    skipped (excluding ACK/NAK); crc_errors/length_errors: frame candidates rejected."""

    frames: int = 0
    crc_errors: int = 0
    length_errors: int = 0
    resyncs: int = 0
    discarded: int = 0
    acks: int = 0
    naks: int = 0


class FrameParser:
    """Incremental frame parser: `feed(chunk)` returns the frames (and, with handshake=True, ACK/NAK bytes
    as ints) completed by that chunk, in stream order.

    replies=True parses LMS replies (`02 80`, status byte, reply codes); False parses host frames (`02 00`).
    Resynchronises on garbage by sliding to the next STX+address pair; after a rejected candidate it resumes
    at the byte after the false STX. For replies a header must carry a known reply code; a B0 length must
    match its info word. The results do not depend on how the stream is cut into chunks.
    """

    def __init__(self, *, replies: bool = True, handshake: bool | None = None) -> None:
        self.replies = replies
        self.handshake = replies if handshake is None else handshake
        self._sync = bytes([STX, REPLY_ADDRESS if replies else HOST_ADDRESS])
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        self._skipping = 0  # bytes skipped since the last frame candidate
        self.stats = ParserStats()

    @property
    def position(self) -> int:
        """Stream offset of the next byte to be fed."""
        return self._base + len(self._buf)

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    @property
    def needed(self) -> int:
        """Bytes still to come for the frame whose start the parser holds (0 when it holds none, or too
        little of one to read its length)."""
        buf = self._buf
        if len(buf) < 4 or buf[0] != STX:
            return 0
        length = buf[2] | (buf[3] << 8)
        if not 1 <= length <= MAX_FRAME_LENGTH:
            return 0
        return max(length + 6 - len(buf), 0)

    def reset(self) -> None:
        """Drop any partial frame (after the host flushed its input)."""
        self._base += len(self._buf)
        self._buf.clear()
        self._skipping = 0

    def _skip(self, segment: bytes | bytearray, out: list) -> None:
        if not self.handshake:
            self.stats.discarded += len(segment)
            self._skipping += len(segment)
            return
        for b in segment:
            if b == ACK:
                self.stats.acks += 1
                out.append(ACK)
            elif b == NAK:
                self.stats.naks += 1
                out.append(NAK)
            else:
                self.stats.discarded += 1
                self._skipping += 1

    def _candidate(self) -> None:
        if self._skipping:
            self.stats.resyncs += 1
            self._skipping = 0

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[Frame | int]:
        """Add bytes; return completed frames (and ACK/NAK ints with handshake) in stream order."""
        buf = self._buf
        buf += chunk
        out: list[Frame | int] = []
        pos = 0
        n = len(buf)
        stats = self.stats
        while pos < n:
            i = buf.find(self._sync, pos)
            if i < 0:
                keep = n - 1 if buf[n - 1] == STX else n
                if keep > pos:
                    self._skip(buf[pos:keep], out)
                pos = keep
                break
            if i > pos:
                self._skip(buf[pos:i], out)
                pos = i
            if n - pos < 5:
                break
            length = buf[pos + 2] | (buf[pos + 3] << 8)
            cmd = buf[pos + 4]
            verdict = self._check_header(buf, pos, n, length, cmd)
            if verdict is None:  # need more bytes to judge
                break
            if verdict == "garbage":
                self._skip(buf[pos : pos + 1], out)
                pos += 1
                continue
            if verdict == "length":
                self._candidate()
                stats.length_errors += 1
                self._skipping += 1
                stats.discarded += 1
                pos += 1
                continue
            end = pos + length + 6
            if end > n:
                break
            raw = bytes(buf[pos:end])
            crc = raw[-2] | (raw[-1] << 8)
            self._candidate()
            if crc != crc16(raw[:-2]):
                stats.crc_errors += 1
                self._skipping += 1
                stats.discarded += 1
                pos += 1
                continue
            reply = self.replies
            frame_end = -3 if reply else -2
            out.append(Frame(raw[1], cmd, raw[5:frame_end], raw[-3] if reply else None, raw, self._base + pos))
            stats.frames += 1
            pos = end
        if pos:
            del buf[:pos]
            self._base += pos
        return out

    def _check_header(self, buf: bytearray, pos: int, n: int, length: int, cmd: int) -> str | None:
        """None (need more bytes), "ok", "garbage" (not a frame start) or "length" (a bad length)."""
        if not self.replies:
            return "ok" if 1 <= length <= MAX_FRAME_LENGTH else "length"
        if cmd not in REPLY_CODES:
            return "garbage"
        if not 2 <= length <= MAX_FRAME_LENGTH:
            return "length"
        if cmd == REPLY_SCAN:
            if n - pos < 7:
                return None
            count = (buf[pos + 5] | (buf[pos + 6] << 8)) & 0x3FF
            if length not in (2 * count + 4, 2 * count + 6):
                return "length"
        return "ok"
