"""Talk to a SICK LMS200 over a serial port: find its baud, configure it, stream scans.

The start-up sequence is docs/lms2xx.md §5: stop any output, ask for status (31h) at 9600, 38400,
19200 and 500000 Bd until a B1 arrives, switch to the requested baud, set the variant (3Bh) and units /
real-time indices (77h, after installation mode) only when they differ from the device's (its EEPROM
allows limited writes), then start continuous output (20 24). Scans are stamped with the host time of their
first byte (int ns, `time.time_ns` clock) estimated from the read time and the byte duration, and never before
the previous frame's last byte (strictly increasing stamps, however late the bytes are read).

The port is any object with read(n)/write(b)/baudrate/timeout/close (pyserial's Serial, or a fake in
tests); `in_waiting` and `reset_input_buffer` are used when present.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from ..base.errors import DeviceError
from ..logs.scan import ScanGeometry
from . import protocol as P
from .frame_parser import FrameParser, ParserStats
from .serial_port import READ_TIMEOUT_S, open_port
from .stream_records import DriverStats, Scan

DETECT_ORDER = (9600, 38400, 19200, 500000)
MODE_TIMEOUT_S = 3.5  # a mode change (20h) can take up to 3 s (TL §4.3)
REPLY_TIMEOUT_S = 0.3
MIN_WAIT_S, MAX_WAIT_S = 0.001, 0.02  # waits for the rest of a telegram: shorter ones are not worth a sleep
PACE_S = 60e-6  # gap between host bytes at 500 kBd (>= 55 us, TL §4.3)


class DeviceDisconnected(DeviceError):
    """The serial device went away mid-run."""


class _NoReply(Exception):
    def __init__(self, nak: bool) -> None:
        super().__init__("no reply")
        self.nak = nak


class LMS2xx:
    """A SICK LMS200 on a serial port. `connect()`, `start()`, then `read_scan()` until done; `stop()`,
    `close()`. Angle in degrees (180 or 100), resolution in degrees (1, 0.5, 0.25), units "mm" or "cm"."""

    def __init__(
        self,
        port,
        *,
        baud: int = 38400,
        angle: int = 180,
        resolution: float = 0.5,
        units: str = "mm",
        indices: bool = False,
        interlaced: bool = False,
        name: str | None = None,
        clock: Callable[[], int] = time.time_ns,
        on_telegram: Callable[[P.Frame, int], None] | None = None,
    ) -> None:
        if baud not in P.BAUD_CODES:
            raise DeviceError(f"baud {baud} not supported (choose 9600, 19200, 38400 or 500000)")
        res = P.RESOLUTIONS.get(float(resolution))
        if res is None or (int(angle), res) not in P.VARIANTS:
            raise DeviceError(f"the LMS200 has no {angle}°/{resolution}° variant (0.25° needs --angle 100)")
        if units not in P.UNITS_M:
            raise DeviceError(f"units must be mm or cm, got {units!r}")
        self.name = name or (port if isinstance(port, str) else getattr(port, "port", None) or "serial port")
        self._port_arg = port
        self.port: Any = None  # a serial.Serial (or a test's stand-in) once open
        self.want_baud, self.angle, self.res, self.units = baud, int(angle), res, units
        self.want_indices, self.interlaced = indices, interlaced
        self.clock = clock
        self.on_telegram = on_telegram
        self.baud = 9600
        self.status: P.Status | None = None
        self.config: P.Config | None = None
        self.measuring_mode = 0
        self.streaming = False
        self.stats = DriverStats()
        self._parser = FrameParser(replies=True)
        self._items: collections.deque[tuple[P.Frame | int, int]] = collections.deque()
        self._chunks: collections.deque[tuple[int, int]] = collections.deque(maxlen=256)  # (end offset, t ns)
        self._line_free_ns = 0  # when the last frame's last byte came (ns): the earliest the next can start
        self._prev: Scan | None = None
        self._partials: dict[int, tuple[P.Telegram, int, bytes]] = {}
        self._received = 0
        self._last_tel: tuple[P.Telegram, int] | None = None

    # ------------------------------------------------------------------------------------ port I/O
    def open(self) -> None:
        if self.port is not None:
            return
        self.port = open_port(self._port_arg, 9600) if isinstance(self._port_arg, str) else self._port_arg
        self._set_baud(9600)
        try:
            self.port.timeout = READ_TIMEOUT_S
        except Exception:  # fakes may not allow it
            pass

    def close(self) -> None:
        """Close the port (also one that was passed in)."""
        if self.port is not None:
            try:
                self.port.close()
            except Exception:
                pass
            self.port = None

    def _set_baud(self, baud: int) -> None:
        try:
            self.port.baudrate = baud
        except (OSError, ValueError) as exc:
            raise DeviceError(f"{self.name}: cannot set {baud} Bd ({exc})") from None
        self.baud = baud

    def _byte_ns(self) -> float:
        return 10e9 / self.baud

    def _write(self, data: bytes) -> None:
        """Send host bytes; at 500 kBd one at a time, >= 55 us apart (TL §4.3)."""
        try:
            if self.baud >= 500000:
                for i in range(len(data)):
                    self.port.write(data[i : i + 1])
                    t = time.perf_counter() + PACE_S
                    while time.perf_counter() < t:
                        pass
            else:
                self.port.write(data)
        except Exception as exc:  # SerialException, OSError, write timeouts
            raise DeviceDisconnected(f"{self.name}: write failed ({exc})") from None

    def _flush_input(self) -> None:
        reset = getattr(self.port, "reset_input_buffer", None)
        if reset is not None:
            try:
                reset()
            except Exception as exc:
                raise DeviceDisconnected(f"{self.name}: {exc}") from None
        self._parser.reset()
        self._items.clear()

    def _poll(self) -> int:
        """Read what has arrived (waiting up to the port timeout for a first byte); parse it.
        Returns the number of bytes read."""
        want = 1
        if self.streaming:
            # the rest of a telegram whose start has arrived comes at the line's byte rate: wait for it
            # rather than waking for every few bytes the port delivers (the start's stamp is already taken)
            need = self._parser.needed
            wait = need * self._byte_ns() * 1e-9
            if wait > MIN_WAIT_S:
                time.sleep(min(wait, MAX_WAIT_S))
                want = need
        try:
            data = self.port.read(want)
            if data:
                more = getattr(self.port, "in_waiting", 0) or 0
                if more:
                    data += self.port.read(more)
        except Exception as exc:  # SerialException, OSError
            raise DeviceDisconnected(f"{self.name}: device disconnected ({exc})") from None
        if not data:
            return 0
        t = self.clock()
        self._received += len(data)
        items = self._parser.feed(data)
        if self.streaming:
            self._update_stats()
        end = self._parser.position
        self._chunks.append((end, t))
        for it in items:
            if isinstance(it, P.Frame):
                stamp = self._after_previous(self._time_of(it.start, end, t), len(it.raw))
                if self.on_telegram is not None:
                    self.on_telegram(it, stamp)
                self._items.append((it, stamp))
            else:
                self._items.append((it, t))
        return len(data)

    def _after_previous(self, stamp: int, n_bytes: int) -> int:
        """A frame's stamp (ns), raised to the end of the frame before it when the estimate is earlier; the line's
        bytes come one after another, so a frame cannot start before the one before it ended. An estimate can:
        after a stall (a loaded machine, a USB adapter's latency timer) the port hands over a burst of bytes that
        arrived at the line's rate but are read at once, and the frames early in a burst are extrapolated back
        past a frame read, late, on its own just before. Stamps are strictly increasing under any load."""
        stamp = max(stamp, self._line_free_ns)
        self._line_free_ns = stamp + max(1, int(n_bytes * self._byte_ns()))
        return stamp

    def _time_of(self, offset: int, end: int, t: int) -> int:
        """Host time (ns) at which the byte at stream `offset` arrived: extrapolated back, at the line's byte
        time, from the end of the first chunk read that held it."""
        for c_end, c_t in reversed(self._chunks):  # the chunks that end past `offset` are the newest
            if c_end <= offset:
                break
            end, t = c_end, c_t
        return int(t - (end - 1 - offset) * self._byte_ns())

    def _transact(
        self, frame: bytes, expect: int, *, timeout: float = REPLY_TIMEOUT_S, retries: int = 3, flush: bool = True
    ) -> P.Frame:
        """Send `frame`, return the reply with code `expect`. Retries on NAK (after 30 ms) or silence."""
        nak = False
        for attempt in range(retries):
            if attempt:
                self.stats.retries += 1
            if flush:
                self._flush_input()
            self._write(frame)
            deadline = time.monotonic() + timeout
            nak = False
            while not nak and time.monotonic() < deadline:
                while self._items:
                    it, _ = self._items.popleft()
                    if it == P.NAK:
                        nak = True
                        self.stats.naks += 1
                        break
                    if isinstance(it, P.Frame) and it.command == expect:
                        return it
                if not nak:
                    self._poll()
            if nak:
                time.sleep(0.03)
        raise _NoReply(nak)

    def _command(self, frame: bytes, expect: int, what: str, *, timeout: float = REPLY_TIMEOUT_S) -> P.Frame:
        try:
            return self._transact(frame, expect, timeout=timeout)
        except _NoReply as exc:
            how = "answered NAK" if exc.nak else "did not answer"
            raise DeviceError(f"{self.name}: the LMS {how} to {what}") from None

    # ----------------------------------------------------------------------------------- start-up
    def connect(self) -> P.Status:
        """Open the port, find the device's baud, switch baud, set variant and units/indices when they
        differ. Returns the device status (B1) as it is after configuration."""
        self.open()
        status = self._detect()
        if self.baud != self.want_baud:
            reply = self._command(
                P.cmd_baud(self.want_baud), P.REPLY_MODE, f"the switch to {self.want_baud} Bd", timeout=MODE_TIMEOUT_S
            )
            if reply.data[:1] != b"\x00":
                raise DeviceError(f"{self.name}: the LMS refused {self.want_baud} Bd (A0 {reply.data.hex()})")
            self._set_baud(self.want_baud)
            time.sleep(0.3)
            try:
                status = P.parse_status(self._transact(P.cmd_status(), P.REPLY_STATUS).data)
            except _NoReply:
                raise DeviceError(
                    f"{self.name}: no answer after switching to {self.want_baud} Bd "
                    "(500000 Bd needs an RS-422 adapter that supports it)"
                ) from None
        if (status.angle_deg, status.resolution_cdeg) != (self.angle, self.res):
            reply = self._command(
                P.cmd_variant(self.angle, self.res), P.REPLY_VARIANT, f"the variant {self.angle}°/{self.res / 100:g}°"
            )
            if reply.data[:1] != b"\x01":
                raise DeviceError(f"{self.name}: the LMS refused the variant {self.angle}°/{self.res / 100:g}°")
        self.config = P.parse_config(
            self._command(P.cmd_read_config(), P.REPLY_READ_CONFIG, "the configuration request").data
        )
        if self.config.units != self.units or (self.want_indices and not self.config.indices):
            self._write_config()
        self.measuring_mode = self.config.measuring_mode
        P.distance_bits(self.measuring_mode)
        self.status = P.parse_status(self._command(P.cmd_status(), P.REPLY_STATUS, "the status request").data)
        self.measuring_mode = self.status.measuring_mode
        return self.status

    def _detect(self) -> P.Status:
        received = 0
        for baud in DETECT_ORDER:
            self._set_baud(baud)
            self._flush_input()
            start = self._received
            self._write(P.cmd_stop())
            deadline = time.monotonic() + 0.1
            while time.monotonic() < deadline:
                self._poll()
            try:
                reply = self._transact(P.cmd_status(), P.REPLY_STATUS, timeout=0.25, retries=2)
            except _NoReply:
                received += self._received - start
                continue
            self.baud = baud
            return P.parse_status(reply.data)
        tried = ", ".join(map(str, DETECT_ORDER))
        if received == 0:
            raise DeviceError(
                f"{self.name}: no answer from an LMS2xx at {tried} Bd (is it powered, connected and on this port?)"
            )
        raise DeviceError(
            f"{self.name}: the device answers garbage at every baud ({tried} Bd; {received} bytes, "
            "no valid LMS2xx telegram); check the wiring and the RS-232/RS-422 setting"
        )

    def _write_config(self) -> None:
        """Installation mode, 77h with the changed units/indices, back to mode 25h (one EEPROM write)."""
        reply = self._command(P.cmd_installation(), P.REPLY_MODE, "installation mode", timeout=MODE_TIMEOUT_S)
        if reply.data[:1] != b"\x00":
            raise DeviceError(
                f"{self.name}: the LMS refused installation mode (A0 {reply.data.hex()}: 01 = bad password, 02 = fault)"
            )
        assert self.config is not None  # read by the caller before installation mode
        block = P.with_config(self.config.raw, units=self.units, indices=True if self.want_indices else None)
        reply = self._command(
            P.cmd_write_config(block), P.REPLY_WRITE_CONFIG, "the configuration write", timeout=MODE_TIMEOUT_S
        )
        if reply.data[:1] != b"\x01":
            raise DeviceError(f"{self.name}: the LMS refused the configuration (units {self.units})")
        self._command(P.cmd_stop(), P.REPLY_MODE, "the return to mode 25h", timeout=MODE_TIMEOUT_S)
        self.config = P.parse_config(block)

    # ------------------------------------------------------------------------------------ stream
    @property
    def period_s(self) -> float:
        """Seconds between telegrams the LMS measures (a rotation when interlaced, else a complete scan)."""
        return P.ROTATION_S if self._interlacing else P.scan_period_s(self.res)

    @property
    def _interlacing(self) -> bool:
        return self.interlaced and self.res != 100

    def geometry(self, frame_id: str = "laser") -> ScanGeometry:
        """LaserScan geometry: beams counter-clockwise from -angle/2; range_max by measuring mode and units;
        scan_time: seconds between scans sent at this baud (rate table)."""
        lost = P.LOST_PER_SENT[self.res][self.baud]
        return ScanGeometry(
            angle_min=float(np.radians(-self.angle / 2)),
            angle_increment=float(np.radians(self.res / 100)),
            n_beams=P.VARIANTS[(self.angle, self.res)],
            range_min=0.0,
            range_max=P.range_max_m(self.measuring_mode, self.units),
            time_increment=0.0,
            scan_time=P.scan_period_s(self.res) * (1 + lost),
            frame_id=frame_id,
        )

    def start(self) -> None:
        """Start continuous (or interlaced) output."""
        frame = P.cmd_interlaced() if self._interlacing else P.cmd_stream()
        self._parser.stats = ParserStats()
        self.stats = DriverStats(naks=self.stats.naks, retries=self.stats.retries)
        reply = self._command(frame, P.REPLY_MODE, "the start of continuous output", timeout=MODE_TIMEOUT_S)
        if reply.data[:1] != b"\x00":
            raise DeviceError(f"{self.name}: the LMS refused continuous output (A0 {reply.data.hex()})")
        self._prev = None
        self._last_tel = None
        self._partials.clear()
        self.streaming = True

    def _update_stats(self) -> None:
        s = self._parser.stats
        st = self.stats
        st.crc_errors, st.length_errors, st.resyncs, st.discarded_bytes = (
            s.crc_errors,
            s.length_errors,
            s.resyncs,
            s.discarded,
        )

    def read_scan(self, timeout: float = 0.2) -> Scan | None:
        """The next complete scan, or None when none arrived within `timeout` seconds.

        Raises DeviceDisconnected when the port fails."""
        deadline = time.monotonic() + timeout
        while True:
            while self._items:
                it, stamp = self._items.popleft()
                if not isinstance(it, P.Frame) or it.command != P.REPLY_SCAN:
                    continue
                scan = self._scan_of(it, stamp)
                if scan is not None:
                    self._update_stats()
                    return scan
            if time.monotonic() >= deadline:
                self._update_stats()
                return None
            self._poll()

    def _scan_of(self, frame: P.Frame, stamp: int) -> Scan | None:
        try:
            tel = P.decode_b0(frame.data, cast(int, frame.status))  # an LMS reply: it has a status
        except P.ProtocolError:
            self.stats.length_errors += 1
            return None
        self.stats.telegrams += 1
        end = stamp + int((len(frame.raw) - 1) * self._byte_ns())
        dropped = self._dropped(tel, stamp)
        if tel.partial and self._interlacing:
            return self._assemble(tel, stamp, end, frame.raw, dropped)
        if len(tel.values) != P.VARIANTS[(self.angle, self.res)]:
            self.stats.length_errors += 1
            return None
        return self._emit(
            Scan(
                stamp,
                end,
                tel.values,
                P.values_to_ranges(tel.values, tel.units, self.measuring_mode),
                tel,
                frame.raw,
                dropped,
            )
        )

    def _dropped(self, tel: P.Telegram, stamp: int) -> int:
        """Telegrams lost since the previous one: by scan index when sent, else by the time gap."""
        prev = self._last_tel
        self._last_tel = (tel, stamp)
        if prev is None:
            return 0
        ptel, pstamp = prev
        if tel.scan_index is not None and ptel.scan_index is not None:
            d = (tel.scan_index - ptel.scan_index - 1) % 256
        else:
            d = max(0, int(round((stamp - pstamp) / (self.period_s * 1e9))) - 1)
        self.stats.dropped += d
        return d

    def _emit(self, scan: Scan) -> Scan:
        self.stats.scans += 1
        self._prev = scan
        return scan

    def _assemble(self, tel: P.Telegram, stamp: int, end: int, raw: bytes, dropped: int) -> Scan | None:
        """Interlaced output: merge the partial scans of one complete scan (offsets in sending order)."""
        offsets = P.partial_offsets(self.res)
        if tel.offset == offsets[0] or dropped:
            if self._partials:
                self.stats.incomplete += 1
            self._partials.clear()
        have = len(self._partials)
        if have >= len(offsets) or tel.offset != offsets[have]:
            if self._partials:
                self.stats.incomplete += 1
            self._partials.clear()
            return None
        self._partials[tel.offset] = (tel, stamp, raw)
        if len(self._partials) < len(offsets):
            return None
        n = P.VARIANTS[(self.angle, self.res)]
        values = np.zeros(n, np.uint16)
        for off, (t, _, _) in self._partials.items():
            pos = P.partial_positions(self.angle, self.res, off)
            if len(t.values) != len(pos):
                self._partials.clear()
                self.stats.length_errors += 1
                return None
            values[pos] = t.values
        first, first_stamp, _ = self._partials[offsets[0]]
        raws = b"".join(r for _, _, r in self._partials.values())
        self._partials.clear()
        merged = P.Telegram(values, first.units, False, 0, first.status, first.scan_index, first.telegram_index)
        return self._emit(
            Scan(
                first_stamp, end, values, P.values_to_ranges(values, first.units, self.measuring_mode), merged, raws, 0
            )
        )

    def stop(self, restore_baud: bool = True) -> None:
        """Stop the output (20 25; B0 frames before the A0 are skipped); optionally go back to 9600 Bd."""
        self._update_stats()
        was = self.streaming
        self.streaming = False
        if self.port is None:
            return
        if was:
            self._command(P.cmd_stop(), P.REPLY_MODE, "the stop request", timeout=1.0)
        if restore_baud and self.baud != 9600:
            reply = self._command(P.cmd_baud(9600), P.REPLY_MODE, "the switch back to 9600 Bd", timeout=1.0)
            if reply.data[:1] == b"\x00":
                self._set_baud(9600)
