"""Saying that numba is compiling: the first run after an install compiles the kernels (tens of seconds)
before a stage's first progress report, which otherwise comes within milliseconds."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

NOTICE = "compiling the numba kernels (once after an install, up to a minute)"


def _timer(delay: float, action: Callable[[], None]) -> threading.Timer:
    timer = threading.Timer(delay, action)
    timer.daemon = True
    timer.start()
    return timer


@contextmanager
def said_if_slow(delay: float = 2.0) -> Iterator[None]:
    """Print NOTICE on stderr when the block is still running after `delay` s (a cache hit loads the kernels
    in about a second; only a compilation takes longer)."""
    import click

    timer = _timer(delay, lambda: click.echo(f"{NOTICE}...", err=True))
    try:
        yield
    finally:
        timer.cancel()


@contextmanager
def compile_notice(bar, task, delay: float = 2.0, *, armed: bool = True) -> Iterator[Callable[[int, int], None]]:
    """A progress callback (done, total) for `task` of the rich Progress `bar`. A report of 0 done starts a
    stage (and `armed` starts one at entry); when the stage's next report is more than `delay` s away,
    the task's description gets NOTICE appended until that report comes."""
    lock = threading.Lock()
    state = {"timer": None, "label": None}

    def late() -> None:
        with lock:
            if state["timer"] is None:
                return
            label = next((t.description for t in bar.tasks if t.id == task), "")
            state["label"] = label
            bar.update(task, description=f"{label}: {NOTICE}")

    def arm() -> None:
        state["timer"] = _timer(delay, late)

    def disarm() -> None:
        timer = state["timer"]
        if timer is not None:
            timer.cancel()
            state["timer"] = None
        if state["label"] is not None:
            bar.update(task, description=state["label"])
            state["label"] = None

    def report(done: int, total: int) -> None:
        with lock:
            disarm()
            bar.update(task, completed=done, total=total)
            if done == 0:
                arm()

    if armed:
        arm()
    try:
        yield report
    finally:
        with lock:
            disarm()
