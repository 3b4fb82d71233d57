"""A virtual SICK LMS200 on a pseudo-terminal, for testing `datmo record` without hardware.

It follows docs/lms2xx.md: power-up at 9600 Bd in mode 25h (180°/0.5°, mm, measuring mode 00), ACK
then reply for every good host frame, NAK on a bad CRC, baud changes acknowledged at the old baud, variant
(3Bh) and configuration (74h/77h, installation mode first) commands, continuous (20 24) and interlaced
(20 2A) output at the real scan period, dropping whole scans below 500 kBd as the rate table says.

A pty has no physical baud rate, so bytes are paced in software (baud/10 bytes per second) and the
emulator compares the speed the host set on the terminal (termios) with the baud it is at: host bytes
sent at the wrong speed are ignored, and the host receives garbage instead of the emulator's output.

Scans come from a `ScanSource` (scan_sources.py: a log, fixed arrays, or a simulated scene: datmo_cli.passes.simulated);
faults (faults.py: garbage, corrupt CRCs, truncated telegrams, dropped bytes, NAKs, a disconnect) can be injected
into the scan stream.
"""

from __future__ import annotations

import collections
import os
import select
import termios
import threading
import time
import tty
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import ConfigError
from . import protocol as P
from .faults import Faults
from .frame_parser import FrameParser
from .scan_sources import ScanSource

SPEEDS = {
    9600: termios.B9600,
    19200: termios.B19200,
    38400: termios.B38400,
    500000: getattr(termios, "B500000", 0x1005),
}


@dataclass
class SentScan:
    """One scan telegram the emulator started to send.

    number: complete-scan number since the stream started (rotation number for interlaced output);
    values: the values in the telegram; fault: None, "crc", "truncate", "drop" or "cut" (interrupted by a
    host request); garbage: bytes of garbage sent just before it; telegram: the intact frame bytes.
    """

    number: int
    values: np.ndarray
    units: str
    measuring_mode: int
    partial: bool
    offset: int
    telegram: bytes
    fault: str | None = None
    garbage: int = 0
    complete: bool = False

    @property
    def good(self) -> bool:
        """Sent whole and unharmed: the host should receive it."""
        return self.fault is None and self.complete

    def ranges(self) -> np.ndarray:
        """The ranges (m, float32) these values stand for."""
        return P.values_to_ranges(self.values, self.units, self.measuring_mode)


@dataclass
class _Out:
    data: bytes
    pos: int = 0
    done: Callable[[], None] | None = None
    scan: SentScan | None = None


@dataclass
class EmulatorStats:
    """Counts of what the emulator received and did."""

    host_frames: int = 0
    naks: int = 0
    wrong_speed_bytes: int = 0
    baud_changes: int = 0
    config_writes: int = 0
    variant_changes: int = 0
    scans_measured: int = 0
    faults: dict[str, int] = field(default_factory=lambda: collections.Counter())


class Emulator:
    """A virtual LMS200 on a pseudo-terminal, run in a thread: `start()`, give `device_path` to the
    host, `stop()`. `sent` lists the scan telegrams sent, in order.

    realtime=False sends scans as fast as the paced line allows (for benchmarks), ignoring the scan period.
    """

    def __init__(
        self,
        source: ScanSource,
        *,
        faults: Faults | None = None,
        seed: int = 0,
        baud: int = 9600,
        angle_deg: int = 180,
        resolution_deg: float = 0.5,
        units: str = "mm",
        measuring_mode: int = 0,
        indices: bool = False,
        status: int = P.STATUS_OK,
        realtime: bool = True,
        on_event: Callable[[str], None] | None = None,
    ) -> None:
        if baud not in P.BAUD_CODES:
            raise ConfigError(f"baud {baud} not supported (choose {', '.join(map(str, P.BAUDS))})")
        res = P.RESOLUTIONS.get(float(resolution_deg))
        if res is None or (int(angle_deg), res) not in P.VARIANTS:
            raise ConfigError(f"no LMS200 variant {angle_deg}°/{resolution_deg}°")
        self.source = source
        self.faults = faults or Faults()
        self._rng = np.random.default_rng(seed)
        self._garble = np.random.default_rng(seed + 1)
        self.baud = baud
        self.angle, self.res = int(angle_deg), res
        self.units, self.measuring_mode = units, measuring_mode
        self.config = P.with_config(P.DEFAULT_CONFIG, units=units, indices=indices)
        self.config = self.config[:5] + bytes([measuring_mode]) + self.config[6:]
        self.status_byte = status
        self.realtime = realtime
        self.on_event = on_event
        self.mode = P.MODE_STOP
        self.installation = False
        self.sent: list[SentScan] = []
        self.stats = EmulatorStats()
        self._scans: Iterator[np.ndarray] | None = None
        self._key: tuple | None = None
        self._queue: collections.deque[_Out] = collections.deque()
        self._parser = FrameParser(replies=False)
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._running = False
        self.disconnected = threading.Event()
        self.master = self.slave = -1
        self.device_path = ""
        self._stream_t0 = 0.0
        self._rotation = 0
        self._telegrams = 0
        self._scan_telegrams = 0
        self._complete: np.ndarray | None = None
        self._first_pending = False

    # -- lifecycle
    def start(self) -> Emulator:
        """Open the pty, prepare the first scans and run the device in a thread."""
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        attrs = termios.tcgetattr(self.slave)
        attrs[4] = attrs[5] = SPEEDS[self.baud]
        termios.tcsetattr(self.slave, termios.TCSANOW, attrs)
        os.set_blocking(self.master, False)
        self.device_path = os.ttyname(self.slave)
        self._source_scans()
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="lms200-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the pty."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self._close()

    def _close(self) -> None:
        for fd in (self.master, self.slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self.slave = -1

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def good_scans(self) -> list[SentScan]:
        """Scans sent whole and unharmed, in order."""
        with self._lock:
            return [s for s in self.sent if s.good]

    # -- host speed
    def host_baud(self) -> int | None:
        """The baud the host set on its end of the pty (None when it is not one of the LMS's)."""
        try:
            speed = termios.tcgetattr(self.master)[5]
        except termios.error:
            return None
        for baud, code in SPEEDS.items():
            if code == speed:
                return baud
        return None

    def _event(self, text: str) -> None:
        if self.on_event is not None:
            self.on_event(text)

    # -- main loop
    def _loop(self) -> None:
        bucket = 0.0
        last = time.perf_counter()
        try:
            while self._running:
                now = time.perf_counter()
                rate = self.baud / 10.0
                bucket = min(bucket + (now - last) * rate, max(64.0, rate * 0.004))
                last = now
                if not self._queue:
                    bucket = min(bucket, 1.0)
                self._schedule(now)
                bucket = self._pump(bucket)
                if self.disconnected.is_set():
                    return
                wait = 0.001 if self._queue or self.mode != P.MODE_STOP else 0.02
                r, _, _ = select.select([self.master], [], [], wait)
                if r:
                    try:
                        data = os.read(self.master, 4096)
                    except (BlockingIOError, InterruptedError):
                        data = b""
                    except OSError:
                        data = b""
                    if data:
                        self._receive(data)
        finally:
            self._running = False

    def _receive(self, data: bytes) -> None:
        if self.host_baud() != self.baud:
            self.stats.wrong_speed_bytes += len(data)
            return
        before = self._parser.stats.crc_errors
        frames = self._parser.feed(data)
        for _ in range(self._parser.stats.crc_errors - before):
            self._cut()
            self.stats.naks += 1
            self._send(bytes([P.NAK]))
        for f in frames:
            if not isinstance(f, P.Frame) or f.address != P.HOST_ADDRESS:  # no ACK/NAK ints here
                continue
            self.stats.host_frames += 1
            self._cut()
            if self.faults.nak > 0:
                self.faults.nak -= 1
                self.stats.naks += 1
                self.stats.faults["nak"] += 1
                self._send(bytes([P.NAK]))
                continue
            self._send(bytes([P.ACK]))
            self._handle(f)

    def _cut(self) -> None:
        """A host request interrupts output: drop what is queued (a telegram in progress is cut short)."""
        while self._queue:
            item = self._queue.popleft()
            if item.scan is not None and item.pos < len(item.data) and item.scan.fault is None:
                item.scan.fault = "cut"
            if item.done is not None and item.scan is None:
                item.done()  # a pending baud change still takes effect

    def _send(self, data: bytes, done: Callable[[], None] | None = None, scan: SentScan | None = None) -> None:
        self._queue.append(_Out(bytes(data), 0, done, scan))

    def _reply(self, payload: bytes, done: Callable[[], None] | None = None) -> None:
        self._send(P.reply_frame(payload, self.status_byte), done)

    def _pump(self, bucket: float) -> float:
        """Write up to `bucket` queued bytes; run completion actions. Returns the unused bucket."""
        while self._queue and bucket >= 1.0:
            item = self._queue[0]
            n = min(int(bucket), len(item.data) - item.pos)
            chunk = item.data[item.pos : item.pos + n]
            if self.host_baud() != self.baud:
                chunk = self._garble.integers(0, 256, len(chunk), np.uint8).tobytes()
            try:
                written = os.write(self.master, chunk) if chunk else 0
            except BlockingIOError:
                written = 0
            except OSError:
                written = 0
                self._queue.clear()
            item.pos += written
            bucket -= written
            if written < n:
                break
            if item.pos >= len(item.data):
                self._queue.popleft()
                if item.scan is not None:
                    item.scan.complete = True
                if item.done is not None:
                    item.done()
        return bucket

    # -- commands
    def _handle(self, f: P.Frame) -> None:
        cmd, data = f.command, f.data
        if cmd == P.CMD_MODE and data:
            sub = data[0]
            if sub == P.MODE_INSTALLATION:
                ok = data[1:] == P.PASSWORD
                self.installation = ok
                self._reply(bytes([P.REPLY_MODE, 0 if ok else 1]))
            elif sub in (P.MODE_STREAM, P.MODE_INTERLACED):
                self._reply(bytes([P.REPLY_MODE, 0]))
                self._start_stream(sub)
            elif sub == P.MODE_STOP:
                self.mode = P.MODE_STOP
                self.installation = False
                self._reply(bytes([P.REPLY_MODE, 0]))
            elif sub in P.CODE_BAUDS:
                new = P.CODE_BAUDS[sub]

                def switch() -> None:
                    self.baud = new
                    self.stats.baud_changes += 1
                    self._event(f"baud {new}")

                self.mode = P.MODE_STOP
                self._reply(bytes([P.REPLY_MODE, 0]), done=switch)
            else:
                self._reply(bytes([P.REPLY_INVALID]))
        elif cmd == P.CMD_STATUS:
            self._reply(
                bytes([P.REPLY_STATUS])
                + P.build_status(
                    operating_mode=self.mode,
                    measuring_mode=self.measuring_mode,
                    angle_deg=self.angle,
                    resolution_cdeg=self.res,
                    baud=self.baud,
                    units=self.units,
                )
            )
        elif cmd == P.CMD_VARIANT and len(data) == 4:
            angle, res = int.from_bytes(data[0:2], "little"), int.from_bytes(data[2:4], "little")
            ok = (angle, res) in P.VARIANTS
            if ok:
                if (angle, res) != (self.angle, self.res):
                    self.stats.variant_changes += 1
                self.angle, self.res = angle, res
                self._event(f"variant {angle}°/{res / 100:g}°")
            self._reply(bytes([P.REPLY_VARIANT, 1 if ok else 0]) + data[0:4])
        elif cmd == P.CMD_READ_CONFIG:
            self._reply(bytes([P.REPLY_READ_CONFIG]) + self.config)
        elif cmd == P.CMD_WRITE_CONFIG and len(data) in (32, P.CONFIG_BYTES):
            ok = self.installation
            if ok:
                block = bytes(data).ljust(P.CONFIG_BYTES, b"\x00")
                conf = P.parse_config(block)
                if conf.units in ("mm", "cm") and conf.measuring_mode in P.DISTANCE_BITS:
                    self.config = block
                    self.units, self.measuring_mode = conf.units, conf.measuring_mode
                    self.stats.config_writes += 1
                    self._event(f"config units {conf.units}, indices {conf.indices}")
                else:
                    ok = False
            self._reply(bytes([P.REPLY_WRITE_CONFIG, 1 if ok else 0]) + bytes(data))
        elif cmd == P.CMD_REQUEST and data[:1] == b"\x01":
            values = self._next_complete()
            self._scan_telegram(values, False, 0, self._rotation)
        else:
            self._reply(bytes([P.REPLY_INVALID]))

    # -- scans
    def _source_scans(self) -> Iterator[np.ndarray]:
        key = (self.angle, self.res, self.units, self.measuring_mode)
        if key != self._key:
            self._scans = iter(self.source.scans(*key))
            self._key = key
            self._complete = next(self._scans)  # prepare the first scan now (simulation set-up)
            self._first_pending = True
        assert self._scans is not None  # made above on the first call
        return self._scans

    def _next_complete(self) -> np.ndarray:
        scans = self._source_scans()
        if self._first_pending:
            self._first_pending = False
            assert self._complete is not None  # made with the scans
            return self._complete
        self._complete = next(scans)
        return self._complete

    def _start_stream(self, mode: int) -> None:
        self._source_scans()
        self.mode = mode
        self._stream_t0 = time.perf_counter()
        self._rotation = 0

    def _period(self) -> float:
        """Seconds between the stream's measurements: a complete scan, or a rotation when interlaced."""
        return P.ROTATION_S if self.mode == P.MODE_INTERLACED else P.scan_period_s(self.res)

    def _schedule(self, now: float) -> None:
        """Measure every scan whose time has come; send those the rate table lets through."""
        if self.mode not in (P.MODE_STREAM, P.MODE_INTERLACED):
            return
        period = self._period()
        if not self.realtime:
            due = self._rotation + (0 if self._queue else 1)
        else:
            due = int((now - self._stream_t0) / period) + 1
            if due - self._rotation > 200:  # far behind (host not reading): skip ahead
                self._rotation = due - 1
        interlaced = self.mode == P.MODE_INTERLACED and self.res != 100
        offsets = P.partial_offsets(self.res) if interlaced else (0,)
        lost = P.LOST_PER_SENT[100 if interlaced else self.res][self.baud]
        hang_up_after = self.faults.disconnect
        while self._rotation < due and self.mode in (P.MODE_STREAM, P.MODE_INTERLACED):
            if hang_up_after is not None and self._scan_telegrams >= hang_up_after:
                return  # the last telegram before the hang-up is on its way
            k = self._rotation
            self._rotation += 1
            self.stats.scans_measured += 1
            phase = k % len(offsets)
            if phase == 0:
                full = self._next_complete()
            else:
                assert self._complete is not None  # phase 0 made it
                full = self._complete
            if k % (1 + lost):
                continue
            if sum(len(o.data) - o.pos for o in self._queue) > 65536:
                continue  # nobody reads: drop like the LMS does when the line is busy
            if interlaced:
                off = offsets[phase]
                values = full[P.partial_positions(self.angle, self.res, off)]
                self._scan_telegram(values, True, off, k)
            else:
                self._scan_telegram(full, False, 0, k)
            if self.disconnected.is_set():
                return

    def _scan_telegram(self, values: np.ndarray, partial: bool, offset: int, number: int) -> None:
        indices = (number, self._telegrams) if P.parse_config(self.config).indices else None
        frame = P.reply_frame(
            P.encode_b0(values, self.units, partial=partial, offset=offset, indices=indices), self.status_byte
        )
        self._telegrams += 1
        scan = SentScan(number, np.array(values, np.uint16), self.units, self.measuring_mode, partial, offset, frame)
        f = self.faults
        burst, data, scan.fault = f.corrupt(frame, self._rng)
        if burst:
            scan.garbage = len(burst)
            self.stats.faults["garbage"] += 1
            self._send(burst)
        if scan.fault:
            self.stats.faults[scan.fault] += 1
        with self._lock:
            self.sent.append(scan)
        self._scan_telegrams += 1
        done = None
        if f.disconnect is not None and self._scan_telegrams >= f.disconnect:
            done = self._hang_up
        self._send(data, done, scan)

    def _hang_up(self) -> None:
        """Disconnect fault: wait until the host has read what was sent, then close the pty."""
        import fcntl
        import struct

        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            try:
                pending = struct.unpack("i", fcntl.ioctl(self.slave, termios.FIONREAD, b"\0\0\0\0"))[0]
            except OSError:
                break
            if pending == 0:
                break
            time.sleep(0.005)
        time.sleep(0.05)
        self._event("disconnect")
        self.mode = P.MODE_STOP
        self._queue.clear()
        self._close()
        self.disconnected.set()
