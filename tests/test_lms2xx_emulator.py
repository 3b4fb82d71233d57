"""The emulator on its own: its command line, fault specs, baud tracking and pacing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from datmo_cli.base.errors import ConfigError
from datmo_cli.lms2xx import protocol as P
from datmo_cli.lms2xx.emulator import Emulator
from datmo_cli.lms2xx.faults import Faults
from datmo_cli.lms2xx.frame_parser import FrameParser
from datmo_cli.lms2xx.scan_sources import ArraySource
from datmo_cli.logs import mcapio

pytestmark = pytest.mark.cli


def test_fault_spec_parsing():
    f = Faults.parse("garbage:0.1, crc:0.05,truncate:0.02,drop:0.01,disconnect:200,nak:1")
    assert (f.garbage, f.crc, f.truncate, f.drop, f.disconnect, f.nak) == (0.1, 0.05, 0.02, 0.01, 200, 1)
    assert Faults.parse(None) == Faults()
    for bad, msg in [
        ("crc:2", "probability"),
        ("boom:1", "unknown"),
        ("disconnect:-1", "count"),
        ("crc:0.6,drop:0.6", "at most 1"),
    ]:
        with pytest.raises(ConfigError, match=msg):
            Faults.parse(bad)


def _exchange(port: serial.Serial, frame: bytes, n: int = 200, wait: float = 0.3) -> list:
    port.reset_input_buffer()
    port.write(frame)
    parser = FrameParser()
    out: list = []
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        out += parser.feed(port.read(n))
    return out


def test_power_up_state_handshake_nak_and_wrong_baud():
    with Emulator(ArraySource(np.full(361, 1000))) as emu, serial.Serial(emu.device_path, 9600, timeout=0.02) as port:
        items = _exchange(port, P.cmd_status())
        assert items[0] == P.ACK and items[1].command == P.REPLY_STATUS
        status = P.parse_status(items[1].data)
        assert (status.baud, status.angle_deg, status.resolution_cdeg, status.units, status.operating_mode) == (
            9600,
            180,
            50,
            "mm",
            0x25,
        )
        bad = P.cmd_status()[:-1] + b"\x00"
        assert _exchange(port, bad) == [P.NAK]
        assert _exchange(port, P.host_frame(b"\x55"))[1].command == P.REPLY_INVALID
        # baud change: A0 at the old baud; then the host must follow
        items = _exchange(port, P.cmd_baud(38400))
        assert items[1].command == P.REPLY_MODE and items[1].data == b"\x00"
        assert _exchange(port, P.cmd_status()) == []  # still at 9600: the LMS does not hear us
        assert emu.stats.wrong_speed_bytes > 0
        port.baudrate = 38400
        assert _exchange(port, P.cmd_status())[1].command == P.REPLY_STATUS
        # variant refused for 180/0.25, accepted for 100/0.25
        items = _exchange(port, P.host_frame(bytes([P.CMD_VARIANT]) + bytes.fromhex("B4001900")))
        assert items[1].data[0] == 0
        items = _exchange(port, P.cmd_variant(100, 25))
        assert items[1].data == bytes.fromhex("01 6400 1900")
        # configuration needs installation mode
        block = P.with_config(P.DEFAULT_CONFIG, units="cm")
        assert _exchange(port, P.cmd_write_config(block))[1].data[0] == 0
        assert _exchange(port, P.cmd_installation(b"SICK_LMX"))[1].data == b"\x01"
        assert _exchange(port, P.cmd_installation())[1].data == b"\x00"
        reply = _exchange(port, P.cmd_write_config(block))[1]
        assert reply.data[0] == 1 and reply.data[1:] == block
        assert P.parse_config(_exchange(port, P.cmd_read_config())[1].data).units == "cm"
        scan = _exchange(port, P.cmd_one_scan())[1]
        tel = P.decode_b0(scan.data)
        assert tel.count == 401 and tel.units == "cm"


def test_output_is_paced_by_the_baud():
    with Emulator(ArraySource(np.full(361, 1000))) as emu, serial.Serial(emu.device_path, 9600, timeout=0.02) as port:
        port.write(P.cmd_one_scan())
        buf = b""
        while not buf:
            buf = port.read(1)
        t0 = time.monotonic()
        while len(buf) < 1 + 732:  # ACK + the B0 frame
            buf += port.read(1000)
        elapsed = time.monotonic() - t0
    assert elapsed == pytest.approx(732 / 960, rel=0.1)  # 9600 Bd: 960 bytes per second


def test_emulate_command_serves_record(tmp_path):
    emu = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from datmo_cli.cli import main; main()",
            "emulate",
            "--scene",
            "static",
            "--link",
            str(tmp_path / "lms"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        path = emu.stdout.readline().strip()
        assert path.startswith("/dev/pts/")
        out = tmp_path / "run.mcap"
        rec = subprocess.run(
            [
                sys.executable,
                "-c",
                "from datmo_cli.cli import main; main()",
                "record",
                "--port",
                str(tmp_path / "lms"),
                "-o",
                str(out),
                "--baud",
                "500000",
                "--scans",
                "10",
            ],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert rec.returncode == 0, rec.stderr
        assert "10 scans" in rec.stderr
        assert len(mcapio.read_run(out)) == 10
    finally:
        emu.send_signal(signal.SIGINT)
        _, err = emu.communicate(timeout=10)
    assert emu.returncode == 130  # Ctrl-C, after the summary and the link's removal
    assert "baud 500000" in err and "sent" in err
    assert "Traceback" not in err and not (tmp_path / "lms").exists()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_emulate_exits_128_plus_the_signal_after_cleaning_up(tmp_path, sig):
    link = tmp_path / "lms"
    emu = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from datmo_cli.cli import main; main()",
            "emulate",
            "--scene",
            "static",
            "--link",
            str(link),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert emu.stdout.readline().strip().startswith("/dev/pts/")
        assert link.is_symlink()
    finally:
        emu.send_signal(sig)
        _, err = emu.communicate(timeout=10)
    assert emu.returncode == 128 + sig, err
    assert err.strip().splitlines()[-1].startswith("emulate: sent ") and "Traceback" not in err
    assert not os.path.lexists(link) and not list(tmp_path.iterdir())
