"""What an LMS2xx driver's stream yields: complete scans (values, ranges, host stamps) and the stream's counts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .protocol import Telegram


@dataclass
class DriverStats:
    """Counts since the stream started (frames rejected, resyncs, scans lost)."""

    scans: int = 0
    telegrams: int = 0
    crc_errors: int = 0
    length_errors: int = 0
    resyncs: int = 0
    discarded_bytes: int = 0
    dropped: int = 0
    naks: int = 0
    retries: int = 0
    incomplete: int = 0  # interlaced sets missing a partial scan

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class Scan:
    """One complete scan: raw values (uint16), ranges (m, float32), host times of its first and last byte
    (ns), real-time indices when sent, and the scans lost just before it (dropped_before)."""

    stamp_ns: int
    end_ns: int
    values: np.ndarray
    ranges: np.ndarray
    telegram: Telegram
    raw: bytes
    dropped_before: int = 0

    @property
    def scan_index(self) -> int | None:
        return self.telegram.scan_index
