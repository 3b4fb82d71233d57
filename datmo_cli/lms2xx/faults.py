"""Faults a virtual LMS200 injects into its scan stream (docs/lms2xx.md §9): garbage before a telegram, a
corrupt CRC, a truncated telegram, a dropped byte, NAKs to host frames, a disconnect."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import ConfigError
from . import protocol as P

GARBAGE_BYTES = np.array([b for b in range(256) if b not in (P.STX, P.ACK, P.NAK)], np.uint8)


@dataclass
class Faults:
    """Faults injected into the scan stream. Probabilities are per scan telegram.

    garbage: a burst of 1-32 random bytes (never STX, ACK or NAK) before the telegram; crc: corrupt its CRC;
    truncate: send only its first 7..len-3 bytes; drop: leave out one byte after the header; (crc, truncate
    and drop exclude each other); disconnect: hang up after that many scan telegrams; nak: answer the first
    that many good host frames with NAK as if their CRC were bad.
    """

    garbage: float = 0.0
    crc: float = 0.0
    truncate: float = 0.0
    drop: float = 0.0
    disconnect: int | None = None
    nak: int = 0

    @classmethod
    def parse(cls, spec: str | None) -> Faults:
        """Faults from `garbage:0.1,crc:0.05,truncate:0.02,drop:0.02,disconnect:200,nak:1`."""
        out = cls()
        if not spec:
            return out
        for item in spec.split(","):
            name, _, value = item.strip().partition(":")
            name = name.strip().lower()
            try:
                if name in ("garbage", "crc", "truncate", "drop"):
                    p = float(value)
                    if not 0.0 <= p <= 1.0:
                        raise ValueError
                    setattr(out, name, p)
                elif name in ("disconnect", "nak"):
                    k = int(value)
                    if k < 0:
                        raise ValueError
                    setattr(out, name, k)
                else:
                    raise ConfigError(f"fault {name!r}: unknown (use garbage, crc, truncate, drop, disconnect, nak)")
            except ValueError:
                kind = "a probability in [0, 1]" if name not in ("disconnect", "nak") else "a count >= 0"
                raise ConfigError(f"fault {item.strip()!r}: the value must be {kind}") from None
        if out.crc + out.truncate + out.drop > 1:
            raise ConfigError("faults crc + truncate + drop must add up to at most 1")
        return out

    def corrupt(self, frame: bytes, rng: np.random.Generator) -> tuple[bytes, bytes, str | None]:
        """(garbage burst to send before it, the bytes sent for it, fault or None) of scan telegram `frame`;
        draws from `rng` in a fixed order: the garbage, then one number choosing crc, truncate or drop."""
        burst = b""
        if self.garbage and rng.random() < self.garbage:
            burst = rng.choice(GARBAGE_BYTES, int(rng.integers(1, 33))).tobytes()
        data, fault = frame, None
        u = rng.random() if (self.crc or self.truncate or self.drop) else 1.0
        if u < self.crc:
            data = frame[:-1] + bytes([frame[-1] ^ int(rng.integers(1, 256))])
            fault = "crc"
        elif u < self.crc + self.truncate:
            data = frame[: int(rng.integers(7, len(frame) - 2))]
            fault = "truncate"
        elif u < self.crc + self.truncate + self.drop:
            i = int(rng.integers(7, len(frame) - 1))
            data = frame[:i] + frame[i + 1 :]
            fault = "drop"
        return burst, data, fault
