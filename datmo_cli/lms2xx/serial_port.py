"""Opening a serial port for an LMS2xx with pyserial: 8N1, raw, no flow control, short reads."""

from __future__ import annotations

from ..base.errors import DeviceError

READ_TIMEOUT_S = 0.02  # port timeout: how long one read waits for a first byte


def open_port(path: str, baud: int = 9600):
    """Open `path` with pyserial: 8N1, raw, no flow control. Raises DeviceError with the reason."""
    import os

    import serial

    if not os.path.exists(path):
        raise DeviceError(f"{path}: cannot open serial port (no such device)")
    try:
        return serial.Serial(
            path,
            baud,
            bytesize=8,
            parity="N",
            stopbits=1,
            timeout=READ_TIMEOUT_S,
            write_timeout=2.0,
            xonxoff=False,
            rtscts=False,
            dsrdtr=False,
            exclusive=True,
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        raise DeviceError(f"{path}: cannot open serial port ({exc})") from None
