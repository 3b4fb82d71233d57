"""Foxglove's playback control for `datmo play` (PlaybackControl): what its playback bar asks (play, pause, seek to a
log time, a speed) and the state the server reports back (playing, paused, ended; the log's time, ns; the speed,
a multiple of the log's own).

The protocol (foxglove-sdk's `playbackControl` capability, which a server that announces its data's time range in
serverInfo's dataStartTime and dataEndTime offers): the client sends a Playback Control Request (binary opcode 3:
play or pause, the speed, and a time to seek to or none, with a request id), the server answers with a Playback
State (binary opcode 5: status, current time, speed, whether it sought, the request's id) and sends one of its
own when its state changes by itself (the log's end). Requests come on the SDK's thread; the thread that plays
the log reads the state between messages and waits on it, so a request takes effect at once, even in a wait for
the next message's time.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

PLAYING, PAUSED, ENDED = "playing", "paused", "ended"  # the statuses reported (the protocol's Playing, Paused, Ended)
MAX_SPEED = 1000.0  # a speed asked for beyond this (× the log's) is taken as this, as --rate bounds it


@dataclass(frozen=True)
class State:
    """The playback's state as reported: `status` (PLAYING, PAUSED or ENDED), `time` (the log's time, ns: the
    last message sent, or the time sought), `speed` (× the log's), `sought` (this state follows a seek)."""

    status: str
    time: int
    speed: float
    sought: bool = False


class PlaybackControl:
    """The playback of a log spanning `start`..`end` (log times, ns) at `speed` times its own: changed by a
    client's `request`, read by the player (`snapshot`, `take_seek`, `sent`, `wait`, `finish`). Thread-safe."""

    def __init__(self, start: int, end: int, speed: float = 1.0) -> None:
        self.start, self.end = int(start), max(int(end), int(start))
        self.speed = float(speed)
        self.paused = False
        self.ended = False
        self.now = self.start  # the log's time of the last message sent (ns)
        self.generation = 0  # counts requests: a wait ends when it changes
        self._seek: int | None = None
        self._cond = threading.Condition()

    def request(self, play: bool, speed: float, seek: int | None) -> State:
        """A client's request: `play` (else pause), `speed` (× the log's; one not above 0, or not finite, leaves
        the speed as it is; above MAX_SPEED, MAX_SPEED), `seek` (a log time in ns to go to, kept within the
        log; None: none). Play after the log's end starts it over from its start. Returns the new state."""
        with self._cond:
            if math.isfinite(speed) and speed > 0:
                self.speed = min(float(speed), MAX_SPEED)
            self.paused = not play
            if seek is None and play and self.ended:
                seek = self.start
            if seek is not None:
                target = min(max(int(seek), self.start), self.end)
                self._seek = self.now = target
                self.ended = False
            self.generation += 1
            self._cond.notify_all()
            return State(self._status(), self.now, self.speed, seek is not None)

    def state(self) -> State:
        with self._cond:
            return State(self._status(), self.now, self.speed)

    def _status(self) -> str:
        return ENDED if self.ended else PAUSED if self.paused else PLAYING

    def snapshot(self) -> tuple[int, bool, float, bool]:
        """(generation, paused, speed, a seek is pending), for the player."""
        with self._cond:
            return self.generation, self.paused, self.speed, self._seek is not None

    def take_seek(self) -> int | None:
        """The time (ns) a client asked to go to, once; None when none is pending."""
        with self._cond:
            seek, self._seek = self._seek, None
            return seek

    def sent(self, stamp: int) -> None:
        """The player sent a message of log time `stamp` (ns)."""
        with self._cond:
            self.now = int(stamp)

    def finish(self) -> State:
        """The player reached the log's end: the state to report (ENDED)."""
        with self._cond:
            self.ended = True
            return State(ENDED, self.now, self.speed)

    def wait(self, generation: int, seconds: float) -> None:
        """Wait up to `seconds`, less when a request comes (or came since `generation` was read)."""
        with self._cond:
            if self.generation == generation and seconds > 0:
                self._cond.wait(seconds)
