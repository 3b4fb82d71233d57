"""How many threads the perception kernels run on (`--threads N` of datmo features and datmo run).

Perception is independent per scan, so a block of scans is split into ranges of consecutive scans that
numba's threads process at once; the results are the same for any number of threads. This is a run-time
setting, not a feature parameter: it never enters an output's parameters.

numba's OpenMP pool (its usual threading layer on Linux) cannot be used in a process forked from one that
started it (numba terminates such a process), and `--jobs` forks workers after warming the kernels up: in
such a child the kernels run on one thread (the jobs already share the cores).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

_POOL_PID: int | None = None  # the process that started numba's thread pool through numba_threads
_DEFAULT: int = 0  # the count a call without one runs on (0: all); set_default, from --threads


def available() -> int:
    """The most threads numba runs (NUMBA_NUM_THREADS; by default the machine's CPUs)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]  # set at numba's import


def set_default(threads: int | None) -> None:
    """The count calls that give none run on in this process (None or 0: all cores): `--threads N`."""
    global _DEFAULT
    if threads is not None and int(threads) < 0:
        raise ValueError(f"threads must be 0 (all) or a positive count, got {threads}")
    _DEFAULT = int(threads or 0)


def resolve(threads: int | None = None) -> int:
    """The threads a call runs on: `threads` (None: the process's default, see set_default; 0: all, see
    available()), at most available(), and 1 in a process forked after its parent started numba's pool.
    ValueError for a negative count."""
    if threads is None:
        threads = _DEFAULT
    if int(threads) < 0:
        raise ValueError(f"threads must be 0 (all) or a positive count, got {threads}")
    n = available() if not threads else min(int(threads), available())
    if n > 1 and _POOL_PID is not None and _POOL_PID != os.getpid():
        return 1
    return max(n, 1)


MIN_SCANS_PER_THREAD = 16  # fewer scans per thread run on one (the parallel kernels' start-up and compile cost)


def for_scans(threads: int, scans: int) -> int:
    """The threads a block of `scans` scans runs on, of `threads`: each gets at least MIN_SCANS_PER_THREAD
    (a run of a few scans never starts, nor compiles, the parallel kernels)."""
    return max(1, min(threads, scans // MIN_SCANS_PER_THREAD))


@contextmanager
def numba_threads(n: int) -> Iterator[int]:
    """Run numba's parallel kernels inside the block on `n` threads (a resolve()d count > 1)."""
    global _POOL_PID
    import numba

    if _POOL_PID is None:
        _POOL_PID = os.getpid()
    before = numba.get_num_threads()
    numba.set_num_threads(n)
    # parts handed out one at a time (not n fixed shares): a thread the OS holds back leaves its share to
    # the others, which matters when other processes share the cores
    chunk = numba.set_parallel_chunksize(1)
    try:
        yield n
    finally:
        numba.set_parallel_chunksize(chunk)
        numba.set_num_threads(before)
