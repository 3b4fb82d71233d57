"""Saying that numba is compiling: the first run after an install compiles the kernels (tens of seconds)
before a command's first progress report, which otherwise comes within milliseconds."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

NOTICE = "compiling the numba kernels (once after an install, up to a minute)"


@contextmanager
def first_report_notice(bar, task, label: str, delay: float = 2.0) -> Iterator[Callable[[int, int], None]]:  # noqa: ANN001
    """A progress callback (done, total) for `task` of the rich Progress `bar`: when its first call is
    more than `delay` s away, the task's description (`label`) says that the kernels are compiling."""
    first = threading.Event()

    def late() -> None:
        if not first.is_set():
            bar.update(task, description=f"{label}: {NOTICE}")

    timer = threading.Timer(delay, late)
    timer.daemon = True

    def report(done: int, total: int) -> None:
        if not first.is_set():
            first.set()
            timer.cancel()
            bar.update(task, description=label)
        bar.update(task, completed=done, total=total)

    timer.start()
    try:
        yield report
    finally:
        timer.cancel()
