"""Writing messages that arrive nearly in time order (an importer's scans and poses) in time order, in
bounded memory.

A whole-run write sorts every message by (log time, channel id), keeping arrival order between equals
(LogWriter.close). `OrderedSink` gives the same order while holding about `2 * window` messages (plus what
came together since the last `flush`): when it holds more, it writes all but the `window` newest (by that
key) and forgets them. A message that arrives after a
later one was written (more than `window` messages late) is written with the next batch, out of order, and
counted in `late`, which the caller reports as a warning. For a log whose messages arrive in order within
the window, the output's messages are those of the whole-run write, in the same order.
"""

from __future__ import annotations

import numpy as np

from .mcapio import LogWriter

WINDOW = 4096   # messages written at once, and held back at least, once more than twice as many are held


class OrderedSink:
    """Time-ordered writing into `writer` through a bounded window (see the module docstring)."""

    def __init__(self, writer: LogWriter, window: int = WINDOW) -> None:
        if window < 1:
            raise ValueError("window must be at least 1")
        self.writer = writer
        self.window = window
        self._stamps: list[np.ndarray] = []
        self._cids: list[np.ndarray] = []
        self._payloads: list[bytes] = []
        self._held = 0
        self._last = (np.iinfo(np.int64).min, -1)   # key of the last message written
        self.late = 0        # messages that came after a later one was written
        self.written = 0
        self.peak = 0        # most messages held at once

    def add(self, cid: int, stamps, payloads: list[bytes]) -> None:
        """Messages of one channel (registered in the writer), in arrival order."""
        stamps = np.asarray(stamps, np.int64)
        if len(stamps) != len(payloads):
            raise ValueError("one stamp per payload")
        if not len(stamps):
            return
        t, c = self._last
        self.late += int(np.sum((stamps < t) | ((stamps == t) & (cid < c))))
        self._stamps.append(stamps)
        self._cids.append(np.full(len(stamps), cid, np.int64))
        self._payloads.extend(payloads)
        self._held += len(stamps)
        self.peak = max(self.peak, self._held)

    def flush(self) -> None:
        """Write the oldest messages when more than twice the window are held (call it after adding what
        came together: a block's scans and poses)."""
        if self._held > 2 * self.window:
            self._write(self._held - self.window)

    def close(self) -> None:
        """Write every message still held."""
        self._write(self._held)

    def _write(self, k: int) -> None:
        if k <= 0:
            return
        stamps, cids = np.concatenate(self._stamps), np.concatenate(self._cids)
        order = np.lexsort((cids, stamps))   # stable: arrival order between equal keys
        out, keep = order[:k], np.sort(order[k:])
        payloads = self._payloads
        for cid in np.unique(cids[out]).tolist():
            pick = out[cids[out] == cid]
            self.writer.write_ids(cid, stamps[pick], [payloads[i] for i in pick.tolist()])
        self.writer.drain()
        last = out[-1]
        self._last = max(self._last, (int(stamps[last]), int(cids[last])))
        self._stamps, self._cids = [stamps[keep]], [cids[keep]]
        self._payloads = [payloads[i] for i in keep.tolist()]
        self._held = len(keep)
        self.written += k
