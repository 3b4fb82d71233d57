"""The driver with an injected, in-memory serial port (no pty, no hardware)."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.base.errors import DeviceError
from datmo_cli.lms2xx import protocol as P
from datmo_cli.lms2xx.driver import DeviceDisconnected, LMS2xx
from datmo_cli.lms2xx.frame_parser import FrameParser

pytestmark = pytest.mark.unit


class FakeLMS:
    """A scripted port: answers host frames at 9600 Bd from memory; streams `scans` after 20 24."""

    def __init__(self, scans: list[bytes], garbage: bytes = b"") -> None:
        self.baudrate = 9600
        self.timeout = 0.0
        self.out = bytearray()
        self.scans = scans
        self.garbage = garbage
        self.parser = FrameParser(replies=False)
        self.commands: list[bytes] = []
        self.closed = False
        self.hang_up = False

    def write(self, data: bytes) -> int:
        for f in self.parser.feed(data):
            self.commands.append(f.payload)
            self.out += bytes([P.ACK])
            if f.command == P.CMD_STATUS:
                self.out += P.reply_frame(b"\xb1" + P.build_status(baud=9600))
            elif f.command == P.CMD_READ_CONFIG:
                self.out += P.reply_frame(b"\xf4" + P.DEFAULT_CONFIG)
            elif f.payload == bytes([P.CMD_MODE, P.MODE_STREAM]):
                self.out += P.reply_frame(b"\xa0\x00")
                for s in self.scans:
                    self.out += self.garbage + s
                self.hang_up = True
            else:
                self.out += P.reply_frame(b"\xa0\x00")
        return len(data)

    def read(self, n: int = 1) -> bytes:
        if not self.out and self.hang_up:
            raise OSError("device disconnected")
        data = bytes(self.out[:n])
        del self.out[:n]
        return data

    def close(self) -> None:
        self.closed = True


def test_driver_with_an_injected_port():
    rng = np.random.default_rng(0)
    values = [rng.integers(0, 8000, 361).astype(np.uint16) for _ in range(3)]
    scans = [P.reply_frame(P.encode_b0(v)) for v in values]
    port = FakeLMS(scans, garbage=b"\x33\x44")
    clock = iter(range(10**9, 10**12, 10**7))
    driver = LMS2xx(port, baud=9600, clock=lambda: next(clock))
    status = driver.connect()
    assert status.baud == 9600 and driver.baud == 9600
    # only status, stop and config were asked: no baud, variant or EEPROM writes
    assert {c[0] for c in port.commands} <= {P.CMD_MODE, P.CMD_STATUS, P.CMD_READ_CONFIG}
    assert bytes([P.CMD_MODE, P.MODE_INSTALLATION]) not in [c[:2] for c in port.commands]
    driver.start()
    got = [driver.read_scan(0.5) for _ in range(3)]
    assert all(np.array_equal(g.values, v) for g, v in zip(got, values, strict=True))
    assert driver.stats.resyncs == 3 and driver.stats.discarded_bytes == 6
    assert all(g.stamp_ns < g.end_ns for g in got)
    with pytest.raises(DeviceDisconnected, match="disconnected"):
        driver.read_scan(0.5)


def test_injected_garbage_port_gives_a_clear_error():
    class Garbage:
        baudrate, timeout = 9600, 0.0

        def __init__(self) -> None:
            self.rng = np.random.default_rng(1)

        def write(self, data: bytes) -> int:
            return len(data)

        def read(self, n: int = 1) -> bytes:
            return self.rng.integers(0, 256, n, np.uint8).tobytes()

        def close(self) -> None:
            pass

    with pytest.raises(DeviceError, match="garbage at every baud"):
        LMS2xx(Garbage(), name="fake").connect()


def test_bad_settings_are_refused():
    with pytest.raises(DeviceError, match="0.25"):
        LMS2xx("/dev/null", angle=180, resolution=0.25)
    with pytest.raises(DeviceError, match="baud"):
        LMS2xx("/dev/null", baud=115200)


class BurstyLMS(FakeLMS):
    """A FakeLMS whose stream comes in scripted bursts: `bursts[k]` = (host time ns when it is read, the indices
    of the scans it holds), as a loaded machine reads a pty or a USB adapter hands over its buffer: a telegram
    read late on its own, then the next ones all at once. `now` is the host clock (the driver's clock)."""

    def __init__(self, scans: list[bytes], bursts: list[tuple[int, list[int]]]) -> None:
        super().__init__([])
        self.stream, self.bursts, self.now = scans, list(bursts), 10**9
        self.pending = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self.out) or len(self.pending)

    def read(self, n: int = 1) -> bytes:
        if self.out or not self.hang_up:  # replies; nothing streams before the 20 24 (hang_up: it came)
            return super().read(n)
        if not self.pending:
            if not self.bursts:
                raise OSError("device disconnected")
            self.now, which = self.bursts.pop(0)
            self.pending += b"".join(self.stream[i] for i in which)
        data = bytes(self.pending[:n])
        del self.pending[:n]
        return data


def test_stamps_are_strictly_increasing_when_bytes_come_in_bursts():
    """A telegram read late on its own, then two read at once 1 ms later: extrapolated back at the line's
    byte rate, the first of those once landed before the one read alone (12.9 ms backwards on a
    loaded machine). A telegram cannot start before the one before it ended."""
    values = [np.full(361, 100 * (k + 1), np.uint16) for k in range(5)]
    scans = [P.reply_frame(P.encode_b0(v)) for v in values]
    ms = 1_000_000
    port = BurstyLMS(scans, [(5_000 * ms, [0]), (5_001 * ms, [1, 2]), (9_000 * ms, [3]), (9_000 * ms + 1, [4])])
    driver = LMS2xx(port, baud=9600, clock=lambda: port.now)
    driver.connect()
    driver.start()
    got = [driver.read_scan(0.5) for _ in range(5)]
    assert all(np.array_equal(g.values, v) for g, v in zip(got, values, strict=True))  # every scan, in order
    stamps = np.array([g.stamp_ns for g in got])
    line = len(scans[0]) * 10e9 / 9600  # ns a telegram takes on the line
    assert np.all(np.diff(stamps) >= int(line)), np.diff(stamps)
    alone = (len(scans[0]) - 1) * 10e9 / 9600  # a telegram read on its own started this long before the read
    assert stamps[0] == int(5_000 * ms - alone) and stamps[3] == int(9_000 * ms - alone)  # their own estimates
