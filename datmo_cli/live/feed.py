"""`datmo record --live` and `datmo node`: scans processed and published as they arrive (LiveFeed), on a thread
of their own, with the odometry that arrives beside them (PoseBuffer)."""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, cast

import numpy as np

from ..logs import mcapio, types
from ..logs.scan import Odometry, ScanGeometry, ScanRun
from .messages import Message, Stages

if TYPE_CHECKING:
    from ..logs.scan import Odometry
    from ..passes.config import DatmoConfig


class LiveFeed:
    """Scans as they arrive (from a recording, or `datmo node`'s subscription), processed and published on a
    thread of their own so that whoever brings them never waits: `scan(stamp, ranges, geometry)` queues a scan;
    `close()` finishes. When processing is behind by `backlog` scans, a scan is dropped and counted: the new one,
    or with `drop_oldest` the oldest waiting. A scan of another geometry than the one before, or stamped before
    it, starts the stages over (new tracks; counted in `restarts`, and `on_restart(why)` is called); one stamped
    the same as the one before is skipped (`skipped`). `odometry`: poses of the sensor's base as they arrive
    (PoseBuffer), which put tracking in the world frame; `scans`: also publish each scan on /scan (the live
    view; `datmo node` does not, the robot has it). A failure stops the feed, not its source (`failure` says
    what it was)."""

    def __init__(
        self,
        server,
        config: DatmoConfig | None = None,
        backlog: int = 256,
        batch: int = 16,
        *,
        odometry: PoseBuffer | None = None,
        drop_oldest: bool = False,
        scans: bool = True,
        on_restart: Callable[[str], None] | None = None,
    ) -> None:
        self.server = server
        self.config = config
        self.batch = batch
        self.odometry = odometry
        self.drop_oldest = drop_oldest
        self.scans = scans
        self.on_restart = on_restart
        self.queue: queue.Queue = queue.Queue(maxsize=backlog)
        self.dropped = 0
        self.published = 0
        self.restarts = 0
        self.skipped = 0
        self.failure: str | None = None
        self._thread = threading.Thread(target=self._run, name="datmo-live", daemon=True)
        self._thread.start()

    def scan(self, stamp_ns: int, ranges: np.ndarray, geometry: ScanGeometry) -> None:
        if self.failure is not None:
            return
        item = (int(stamp_ns), np.array(ranges, np.float32), geometry)
        try:
            self.queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1
            if not self.drop_oldest:
                return
            try:
                self.queue.get_nowait()
            except queue.Empty:  # the feed took them all meanwhile
                pass
            try:
                self.queue.put_nowait(item)
            except queue.Full:  # another caller filled it again: this one goes
                pass

    def close(self, timeout: float = 5.0) -> None:
        """Stop the thread (after the queued scans, waiting at most `timeout` seconds)."""
        try:
            self.queue.put(None, timeout=timeout)
        except queue.Full:  # the thread has stopped (a failure) with the queue full
            return
        self._thread.join(timeout)

    def _run(self) -> None:
        stages: Stages | None = None
        last: tuple[int, ScanGeometry] | None = None
        try:
            while True:
                items = [self.queue.get()]
                while items[-1] is not None and len(items) < self.batch:
                    try:
                        items.append(self.queue.get_nowait())
                    except queue.Empty:
                        break
                run: list[tuple[int, np.ndarray, ScanGeometry]] = []
                for item in items:
                    if item is None:
                        break
                    stamp, _, geometry = item
                    why = None if last is None else _why_restart(last, stamp, geometry)
                    if why == "":
                        self.skipped += 1
                        continue
                    if why is not None:
                        self._publish(stages, run)
                        run, stages = [], None
                        self.restarts += 1
                        if self.on_restart is not None:
                            self.on_restart(why)
                    if stages is None:
                        stages = Stages(
                            cast("Odometry | None", self.odometry),  # a PoseBuffer serves as one: at, frame_id, len
                            geometry,
                            self.config,
                            has_tf=self.odometry is not None,
                        )
                    run.append(item)
                    last = (stamp, geometry)
                self._publish(stages, run)
                if items[-1] is None:
                    return
        except Exception as exc:  # the view may fail; the recording goes on
            self.failure = f"{type(exc).__name__}: {exc}"

    def _publish(self, stages: Stages | None, scans: list[tuple[int, np.ndarray, ScanGeometry]]) -> None:
        """Process `scans` (one geometry, stamps increasing) and publish them and what they gave."""
        from ..logs.scan import encode_scan

        if not scans or stages is None:
            return
        geometry = scans[0][2]
        run = ScanRun(np.array([s for s, _, _ in scans], np.int64), np.stack([r for _, r, _ in scans]), geometry)
        derived = stages.messages(run)
        for stamp, ranges, g in scans:
            self.server.time(stamp)
            if self.scans:
                self.server.publish(Message(stamp, mcapio.TOPIC_SCAN, types.LASERSCAN, encode_scan(stamp, ranges, g)))
        for m in derived:
            self.server.publish(m)
        self.published += len(scans)


def _why_restart(last: tuple[int, ScanGeometry], stamp: int, geometry: ScanGeometry) -> str | None:
    """Why a scan stamped `stamp` (ns) of `geometry` cannot follow the scan `last` (stamp, geometry) in one run
    of the stages: a sentence; "" when it repeats the last scan's stamp; None when it follows."""
    before, g = last
    if not geometry.same_beams(g) or geometry.frame_id != g.frame_id:
        return (
            f"the scans' geometry changed ({g.n_beams} beams from {math.degrees(g.angle_min):g} deg in "
            f"{g.frame_id!r}, now {geometry.n_beams} from {math.degrees(geometry.angle_min):g} deg in "
            f"{geometry.frame_id!r})"
        )
    if stamp == before:
        return ""
    if stamp < before:
        return f"the scans' time went back by {(before - stamp) / 1e9:.3f} s"
    return None


class PoseBuffer:
    """Odometry as it arrives, for LiveFeed: the latest `keep` poses of the sensor's base in the world frame
    (stamp ns, x and y in metres, theta in radians), read as log.scan.Odometry is (`at`, `len`, the frames).
    A pose stamped at or before the latest one is not kept (`stale` counts them). Thread-safe."""

    def __init__(self, keep: int = 1024) -> None:
        self.keep = keep
        self.frame_id, self.child_frame_id = "odom", "base_link"
        self.stale = 0
        self._poses: list[tuple[int, float, float, float]] = []
        self._lock = threading.Lock()

    def add(self, stamp: int, x: float, y: float, theta: float, frame_id: str = "", child_frame_id: str = "") -> None:
        with self._lock:
            if self._poses and stamp <= self._poses[-1][0]:
                self.stale += 1
                return
            self._poses.append((int(stamp), float(x), float(y), float(theta)))
            if len(self._poses) > 2 * self.keep:
                del self._poses[: -self.keep]
            self.frame_id = frame_id or self.frame_id
            self.child_frame_id = child_frame_id or self.child_frame_id

    def __len__(self) -> int:
        with self._lock:
            return len(self._poses)

    def at(self, stamps: np.ndarray) -> np.ndarray:
        """Poses (K x 3: x, y, theta) at `stamps` (ns), interpolated; the latest held past the end."""
        with self._lock:
            recent = self._poses[-self.keep :]
        if not recent:
            raise ValueError("no odometry has arrived")
        xyt = np.array([p[1:] for p in recent], np.float64)
        stamps_ns = np.fromiter((p[0] for p in recent), np.int64, len(recent))
        return Odometry(stamps_ns, xyt[:, 0], xyt[:, 1], xyt[:, 2]).at(stamps)
