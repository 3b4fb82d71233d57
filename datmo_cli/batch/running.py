"""Running a prepared batch (`run_many`): each task's manifest line appended as it finishes, and Ctrl-C or
SIGTERM ending the batch with its finished outputs and lines kept."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from ..base.errors import DatmoError
from .locations import new_journal, remove_recorded
from .manifest import CANCELLED, FAILED, manifest_line

if TYPE_CHECKING:
    from .executors import Executor
    from .plan import Batch


class BatchInterrupted(DatmoError):
    """Ctrl-C: the batch stopped; finished outputs and their manifest lines are kept."""

    exit_code = 130


_DEFERRING: list[int] = []  # SIGINTs caught while a deferring block runs (the outermost block owns it)


@contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) that arrives inside the block until the end of the outermost such block (main
    thread only)."""
    import signal

    global _DEFERRING
    if threading.current_thread() is not threading.main_thread() or _DEFERRING is not _NOT_DEFERRING:
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda sig, frame: caught.append(sig))
    _DEFERRING = caught
    try:
        yield
    finally:
        _DEFERRING = _NOT_DEFERRING
        signal.signal(signal.SIGINT, previous)
    if caught:
        if callable(previous) and previous is not signal.default_int_handler:
            previous(signal.SIGINT, None)  # an executor's own Ctrl-C handler (see cluster._interrupt_flag)
        else:
            raise KeyboardInterrupt


_NOT_DEFERRING = _DEFERRING


def run_many(
    batch: Batch,
    executor: Executor,
    *,
    on_record: Callable[[dict], None] | None = None,
    on_scans: Callable[[int, int, int], None] | None = None,
) -> list[dict]:
    """Run a prepared batch: skipped inputs' lines first, then each task's line as it finishes, all
    appended to the manifest. Returns this batch's lines in input order. Ctrl-C: the executor stops its
    tasks, partial files are removed and BatchInterrupted says what is kept."""

    def finished(rec: dict) -> None:
        if rec["status"] == CANCELLED:
            return
        with _interrupt_deferred():  # a line is written and counted whole, or not at all
            batch.manifest.append(manifest_line(rec))
            batch.records[rec["input"]] = rec
        if on_record:
            on_record(rec)

    from ..base.outputs import Terminated, discard

    journal = new_journal()  # the tasks' temporary files, by name: removed when a task leaves one behind
    for t in batch.tasks:
        t.journal = journal

    def clean_up() -> None:
        remove_recorded(journal)
        discard(journal)

    for rec in batch.skipped:
        finished(rec)
    try:
        executor.run(batch.tasks, finished, on_scans)
    except Terminated:  # SIGTERM, SIGHUP: the same clean-up; the CLI exits 143 or 129
        clean_up()
        batch.manifest.close()
        raise
    except KeyboardInterrupt:
        clean_up()
        batch.manifest.close()
        done = sum(r["status"] != FAILED for r in batch.records.values())
        raise BatchInterrupted(
            f"interrupted: {done} of {batch.total} inputs done and in {batch.manifest.path}; "
            "run the same command again to do the rest"
        ) from None
    clean_up()  # left by workers that died mid-write
    batch.manifest.close()
    index = {out: i for i, out in enumerate(batch.outputs)}
    return sorted(batch.records.values(), key=lambda r: index.get(r["output"], len(index)))
