"""The conventions a CARMEN log's scans follow once parsed: beam angles, the range that means "no return", and
what is done to stamps that do not increase.

Conventions (stated in docs/import.md):

- Beam angles (radians, counter-clockwise from the laser's x axis): RAWLASER/ROBOTLASER give start angle
  and resolution. FLASER/RLASER with n = 181 or 361 (or any odd n) beams span -90°..+90° inclusive; with
  n = 180 or 360 (any even n) they follow CARMEN's convention for those sensors: beam i at
  -90° + i·180°/n, so 1° or 0.5° steps from -90° to +89° or +89.5°. ``PARAM laser_front_laser_flipped``
  on reverses the beam order.
- No return: a reading at or above the sensor's maximum becomes +inf (REP 117) and range_max is that
  maximum. RAWLASER/ROBOTLASER state it (max_range). For FLASER/RLASER it is taken from the file's
  no-return codes: 81.83 m when readings reach SICK's 8183-8191 cm error codes, else 50 m when readings
  reach CARMEN's 50 m cap (values such as 51.15 m), else 32.767 m (0x7FFF mm) when that code occurs,
  else 81.83 m (nothing is marked). ``PARAM robot_front_laser_max`` is not trusted (edmonton says 10 m
  and holds 51 m readings).
- Stamps: ipc_timestamp seconds -> int64 ns. When up to 5 % of them go backwards or repeat (intel), each
  such stamp is set 1 ms after the one before; when more do (several logs print them with 6 significant
  digits, or as 0), all are synthesised at 1 s per scan from the first stamp (0 when negative). Both warn.
  A stamp that is not finite, or beyond int64 nanoseconds (after 2262), is a bad stamp too: repaired alone
  (set 1 ms after the one before) when the bad ones are at most 5 %; all are synthesised only when more are,
  or when the first stamp is one (nothing before it to repair it from). The warning names the scans repaired.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

SICK_CODE_M = 81.83  # SICK LMS cm mode: 8183..8191 are error / no-return codes
CARMEN_CAP_M = 50.0  # CARMEN logs cap no-return readings at (or just above) 50 m
MM_CODE_M = 32.767  # 0x7FFF mm
SYNTH_PERIOD_NS = 1_000_000_000
MAX_STAMP_S = 9.2e9  # the largest stamp, seconds, that int64 nanoseconds hold (2^63 ns is 9.22e9 s)


def flaser_angles(n_beams: int) -> tuple[float, float]:
    """(angle_min, angle_increment), radians, of a FLASER/RLASER scan of `n_beams` beams (module docstring)."""
    if n_beams < 2:
        return -np.pi / 2, np.pi
    if n_beams % 2 == 0:
        return -np.pi / 2, np.pi / n_beams
    return -np.pi / 2, np.pi / (n_beams - 1)


def no_return_limit(ranges: np.ndarray, stated_max: float | None = None) -> float:
    """The range (m) at or above which a reading means "no return" (see the module docstring)."""
    top = float(np.nanmax(ranges)) if ranges.size else 0.0
    return no_return_limit_of(top, stated_max)


def no_return_limit_of(top: float, stated_max: float | None) -> float:
    """no_return_limit from the largest reading (`top`, NaN when there is none)."""
    if stated_max is not None and stated_max > 0:
        return float(stated_max)
    if top >= SICK_CODE_M - 1e-6:
        return SICK_CODE_M
    if top >= CARMEN_CAP_M:
        return CARMEN_CAP_M
    if abs(top - MM_CODE_M) < 1e-6:
        return MM_CODE_M
    return SICK_CODE_M


def stamps_ns(stamps_s: np.ndarray) -> tuple[np.ndarray, str | None]:
    """(int64 ns stamps, what was done to them or None) from ipc_timestamp seconds (module docstring).

    Increasing stamps are kept. When at most 5 % of the steps go backwards or repeat, each such stamp is
    set 1 ms after the one before ("repaired"); otherwise all are synthesised at 1 s per scan from the
    first stamp (0 when negative or not finite).
    """
    check = StampCheck()
    for t in np.asarray(stamps_s, np.float64).tolist():
        check.add(t)
    note = check.note(lambda: np.asarray(stamps_s, np.float64))
    return check.apply(np.asarray(stamps_s, np.float64)), note


class StampCheck:
    """`stamps_ns` over stamps that come one at a time: `add` each (seconds), then `note` what is done to
    them, then `apply` it to the same stamps block by block, in order. Holds a few numbers."""

    SHOWN = 5  # scans the note names

    def __init__(self) -> None:
        self.n = 0
        self.first_bad = False  # the first stamp is not finite, negative or beyond MAX_STAMP_S
        self.bad = 0  # steps that go backwards or repeat (from the last usable stamp)
        self.invalid = 0  # stamps that are not finite or beyond MAX_STAMP_S
        self.which: list[int] = []  # the first SHOWN scans (from 0) whose stamp is bad
        self._prev: float | None = None  # the last usable stamp
        self.t0 = 0.0
        self._done = 0  # stamps applied so far
        self._last_ns = 0

    @property
    def ok(self) -> bool:
        return not self.first_bad

    def add(self, t: float) -> None:
        i = self.n
        self.n += 1
        if i == 0:
            self.t0 = t
        usable = math.isfinite(t) and t < MAX_STAMP_S and (i > 0 or t >= 0)
        if not usable:
            self.invalid += 1
            self.first_bad = self.first_bad or i == 0
        elif self._prev is not None and t - self._prev <= 0:
            self.bad += 1
        else:
            self._prev = t
            return
        if len(self.which) < self.SHOWN:
            self.which.append(i)

    @property
    def mode(self) -> str:
        """ "keep", "repair" or "synthesise"."""
        wrong = self.bad + self.invalid
        if self.n and self.ok and wrong == 0:
            return "keep"
        if self.n and self.ok and wrong <= 0.05 * self.n:
            return "repair"
        return "synthesise"

    def _scans(self) -> str:
        more = ", ..." if self.bad + self.invalid > len(self.which) else ""
        return f"scan{'s' if len(self.which) > 1 else ''} {', '.join(map(str, self.which))}{more}"

    def _what(self) -> str:
        parts = [f"{self.bad} stamps go backwards or repeat"] if self.bad else []
        if self.invalid:
            parts.append(f"{self.invalid} {'is' if self.invalid == 1 else 'are'} not a number or out of range")
        return " and ".join(parts)

    def note(self, stamps: Callable[[], np.ndarray]) -> str | None:
        """What is done to the stamps (None: kept), naming the first scans whose stamps are bad; `stamps()`
        gives them all, for the count of distinct stamps of the synthesised case only."""
        mode = self.mode
        if mode == "keep":
            return None
        if mode == "repair":
            return f"{self._what()}; each set 1 ms after the one before ({self._scans()})"
        if not self.invalid:
            distinct = len(np.unique(stamps()))
            return f"not increasing ({distinct} distinct of {self.n}); synthesised at 1 s per scan"
        why = "the first stamp is one" if self.first_bad else "more than 5 % of the stamps are bad"
        return f"{self._what()} ({self._scans()}) and {why}; all {self.n} synthesised at 1 s per scan"

    def rewind(self) -> None:
        """Apply from the first stamp again."""
        self._done, self._last_ns = 0, 0

    def apply(self, t: np.ndarray) -> np.ndarray:
        """ns stamps of the next stamps `t` (s), carrying on from the block before."""
        t = np.asarray(t, np.float64)
        first, mode = self._done, self.mode
        self._done += len(t)
        if mode == "keep":
            return np.round(t * 1e9).astype(np.int64)
        if mode == "repair":
            usable = np.isfinite(t) & (t < MAX_STAMP_S)
            ns = np.round(np.where(usable, t, 0.0) * 1e9).astype(np.int64)
            last = self._last_ns
            for i in range(len(ns)):  # per scan, a few thousand at most
                if (first or i) and (ns[i] <= last or not usable[i]):
                    ns[i] = last + 1_000_000
                last = int(ns[i])
            self._last_ns = last
            return ns
        t0 = float(self.t0) if self.n and np.isfinite(self.t0) and 0 <= self.t0 < MAX_STAMP_S else 0.0
        return int(round(t0 * 1e9)) + np.arange(first, first + len(t), dtype=np.int64) * SYNTH_PERIOD_NS
