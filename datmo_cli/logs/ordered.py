"""Writing messages that arrive nearly in time order (an importer's scans and poses) in time order, in
bounded memory.

A whole-run write sorts every message by (log time, channel id), keeping arrival order between equals
(LogWriter.close). `OrderedSink` gives the same order while holding about `2 * window` messages (plus what
came together since the last `flush`): when it holds more, it writes all but the `window` newest (by that
key) and forgets them. A message that arrives after a
later one was written (more than `window` messages late) is written with the next batch, out of order, and
counted in `late`, which the caller reports as a warning. For a log whose messages arrive in order within
the window, the output's messages are those of the whole-run write, in the same order.

Scan stamps (the channels given as `unique`): a message stamped before one that came earlier on its channel
is counted in `reordered` (it is written in its time order, as every message is), and a message with the
stamp of one already taken on its channel is dropped and counted in `dropped` (the first to come is kept):
a tracker cannot take two scans of one instant. `order_note` words both as one warning; `stamp_order`
does the same for a whole run held in memory.
"""

from __future__ import annotations

import numpy as np

from .mcap_writer import LogWriter

_MIN = int(np.iinfo(np.int64).min)
WINDOW = 4096  # messages written at once, and held back at least, once more than twice as many are held


class OrderedSink:
    """Time-ordered writing into `writer` through a bounded window (see the module docstring)."""

    def __init__(self, writer: LogWriter, window: int = WINDOW, unique: tuple[int, ...] = ()) -> None:
        if window < 1:
            raise ValueError("window must be at least 1")
        self.writer = writer
        self.window = window
        self.unique = set(unique)
        self._stamps: list[np.ndarray] = []
        self._cids: list[np.ndarray] = []
        self._seqs: list[np.ndarray] = []  # each message's index among its channel's arrivals
        self._backs: list[np.ndarray] = []  # whether it came after a later-stamped one on its channel
        self._payloads: list[bytes] = []
        self._held = 0
        self._last = (_MIN, -1)  # key of the last message written
        self._arrived: dict[int, int] = {}  # channel -> messages that came
        self._top: dict[int, int] = {}  # unique channel -> largest stamp that came
        self._taken: dict[int, int] = {}  # unique channel -> stamp of the last message written
        self.late = 0  # messages that came after a later one was written
        self.reordered = 0  # messages of a unique channel stamped before one that came earlier on it (and kept)
        self.first_reordered: int | None = None  # the first such message's index on its channel
        self.dropped = 0  # messages of a unique channel with the stamp of one already taken
        self.first_dropped: int | None = None
        self.written = 0
        self.peak = 0  # most messages held at once

    def add(self, cid: int, stamps, payloads: list[bytes]) -> None:
        """Messages of one channel (registered in the writer), in arrival order."""
        stamps = np.asarray(stamps, np.int64)
        if len(stamps) != len(payloads):
            raise ValueError("one stamp per payload")
        if not len(stamps):
            return
        t, c = self._last
        self.late += int(np.sum((stamps < t) | ((stamps == t) & (cid < c))))
        first = self._arrived.get(cid, 0)
        self._arrived[cid] = first + len(stamps)
        back = np.zeros(len(stamps), bool)
        if cid in self.unique:
            top = np.maximum.accumulate(np.concatenate([[self._top.get(cid, _MIN)], stamps]))
            back = stamps < top[:-1]
            self._top[cid] = int(top[-1])
        self._stamps.append(stamps)
        self._cids.append(np.full(len(stamps), cid, np.int64))
        self._seqs.append(np.arange(first, first + len(stamps), dtype=np.int64))
        self._backs.append(back)
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
        stamps, cids, seqs, backs = (np.concatenate(a) for a in (self._stamps, self._cids, self._seqs, self._backs))
        order = np.lexsort((cids, stamps))  # stable: arrival order between equal keys
        out, keep = order[:k], np.sort(order[k:])
        payloads = self._payloads
        for cid in np.unique(cids[out]).tolist():
            pick = out[cids[out] == cid]
            if cid in self.unique:
                pick = self._drop_repeats(cid, pick, stamps, seqs)
                back = seqs[pick[backs[pick]]]
                if len(back):
                    self.reordered += len(back)
                    first = int(back.min())
                    self.first_reordered = first if self.first_reordered is None else min(self.first_reordered, first)
            self.writer.write_ids(cid, stamps[pick], [payloads[i] for i in pick.tolist()])
        self.writer.drain()
        last = out[-1]
        self._last = max(self._last, (int(stamps[last]), int(cids[last])))
        self._stamps, self._cids, self._seqs, self._backs = [stamps[keep]], [cids[keep]], [seqs[keep]], [backs[keep]]
        self._payloads = [payloads[i] for i in keep.tolist()]
        self._held = len(keep)
        self.written += k

    def _drop_repeats(self, cid: int, pick: np.ndarray, stamps: np.ndarray, seqs: np.ndarray) -> np.ndarray:
        """`pick` (a unique channel's messages to write, in time order) without those stamped as the one
        before them (or as the channel's last written), counted in `dropped`."""
        st = stamps[pick]
        before = np.concatenate([[self._taken.get(cid, _MIN)], st[:-1]])
        repeat = st == before
        self._taken[cid] = max(self._taken.get(cid, _MIN), int(st[-1]))
        if not repeat.any():
            return pick
        self.dropped += int(repeat.sum())
        first = int(seqs[pick[repeat]].min())
        self.first_dropped = first if self.first_dropped is None else min(self.first_dropped, first)
        return pick[~repeat]


def stamp_order(stamps) -> tuple[np.ndarray, int, int | None, int, int | None]:
    """What OrderedSink does to one unique channel's stamps, for a whole run held in memory: (indices of the
    messages to keep, in time order; how many of them were stamped before an earlier one, the first's index;
    how many repeat a stamp taken before, the first's index)."""
    stamps = np.asarray(stamps, np.int64)
    if not len(stamps):
        return np.zeros(0, np.int64), 0, None, 0, None
    order = np.argsort(stamps, kind="stable")
    st = stamps[order]
    repeat = np.concatenate([[False], st[1:] == st[:-1]])
    keep = order[~repeat]
    dropped = np.zeros(len(stamps), bool)
    dropped[order[repeat]] = True
    back = np.flatnonzero((stamps[1:] < np.maximum.accumulate(stamps)[:-1]) & ~dropped[1:]) + 1
    return (
        keep,
        len(back),
        int(back[0]) if len(back) else None,
        int(repeat.sum()),
        int(order[repeat].min()) if repeat.any() else None,
    )


def order_note(
    src, total: int, reordered: int, first_reordered: int | None, dropped: int, first_dropped: int | None
) -> str | None:
    """The one-line warning for `src`'s scans (`total` of them) that came out of time order (`reordered`,
    the first's index) or repeat a stamp (`dropped`); None when there are neither."""
    parts = []
    if reordered:
        parts.append(
            f"{reordered} stamped before an earlier one (first at scan {first_reordered}), written in time order"
        )
    if dropped:
        parts.append(f"{dropped} repeat the stamp of another (first at scan {first_dropped}), dropped")
    if not parts:
        return None
    return f"{src}: scan stamps not increasing: of {total} scans, " + "; ".join(parts)
