"""Where a batch's tasks run: the Executor interface, and LocalExecutor (`--jobs N`: processes on this machine,
each ending with the batch's process). The Dask executor is cluster.DaskExecutor."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable

from .task import Task, failed, run_task


class Executor:
    """Runs tasks somewhere; `run_many` calls `on_record(record)` in this process as each task finishes (in any
    order) and `on_scans(task_index, done, total)` when it can follow scans; Ctrl-C stops the workers'
    tasks (their partial outputs dropped) and is raised again."""

    workers: int = 1
    where: str = "local"

    def run(
        self,
        tasks: list[Task],
        on_record: Callable[[dict], None],
        on_scans: Callable[[int, int, int], None] | None = None,
    ) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


class LocalExecutor(Executor):
    """`--jobs N`: one process per job on this machine (forked after warm_up, so kernels are loaded), at most
    one per task; each worker ends with the batch's process, however that ends (die_with_parent)."""

    def __init__(self, jobs: int | None = None) -> None:
        self.workers = jobs or os.cpu_count() or 1
        self.where = _processes(1)

    def run(self, tasks, on_record, on_scans=None) -> None:
        if not tasks:
            return
        n = min(self.workers, len(tasks))
        self.where = _processes(n)  # what ran them, not what --jobs allowed
        if n <= 1:
            for t in tasks:
                on_record(run_task(t, scans=_scans_of(t.index, on_scans)))
            return
        self._pool(tasks, n, on_record, on_scans)

    def _pool(self, tasks, n, on_record, on_scans) -> None:
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
        from concurrent.futures.process import BrokenProcessPool

        from ..passes.warm import warm_up

        warm_up()
        ctx = multiprocessing.get_context("fork") if hasattr(os, "fork") else multiprocessing.get_context()
        queue = ctx.Queue()  # (task, scans done, scans) from the workers; handed over as they start
        pool = ProcessPoolExecutor(
            max_workers=n, mp_context=ctx, initializer=_worker_started, initargs=(os.getpid(), queue)
        )
        try:
            futures = {pool.submit(_queued_task, t): t for t in tasks}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
                _drain(queue, on_scans)
                for fut in done:
                    t = futures[fut]
                    try:
                        on_record(fut.result())
                    except BrokenProcessPool as exc:
                        on_record(failed(t, f"worker died ({exc})"))
            _drain(queue, on_scans)
        except BaseException:
            workers = list(getattr(pool, "_processes", {}).values())
            for p in workers:
                p.terminate()  # a task still running must not finish an output after the batch stopped
            for p in workers:  # one that does not end (its exit waits on a lock) is killed: no hang on Ctrl-C
                p.join(STOP_GRACE)
                if p.is_alive():
                    p.kill()
            pool.shutdown(wait=True, cancel_futures=True)
            queue.close()
            raise
        pool.shutdown(wait=True)
        queue.close()


STOP_GRACE = 3.0  # s a --jobs worker has to end after SIGTERM when the batch stops, before SIGKILL


def _scans_of(index: int, on_scans: Callable[[int, int, int], None] | None) -> Callable[[int, int], None] | None:
    """A task's own progress callback (scans done, of how many) for the batch's `on_scans(index, done, total)`."""
    if on_scans is None:
        return None
    return lambda done, total: on_scans(index, done, total)


def _processes(n: int) -> str:
    return f"{n} local process{'es' if n > 1 else ''}"


_SCANS: list = []  # in a --jobs worker: the queue its tasks report their scans on


def _worker_started(parent: int, queue) -> None:
    """A --jobs worker's start: end with the batch's process; keep the queue scans are reported on."""
    _SCANS[:] = [queue]
    # scan counts are progress only: a worker that ends must not wait to flush them (a stopped batch hung on it)
    queue.cancel_join_thread()
    die_with_parent(parent)


def die_with_parent(parent: int) -> None:
    """Make this process (a worker of process `parent`) end when `parent` ends, however it ends (SIGKILL
    too): on Linux the kernel sends SIGTERM when the parent dies (prctl PR_SET_PDEATHSIG), elsewhere a thread
    watches the parent. The worker then removes its temporary files and exits 143 at once; a SIGTERM while the
    parent lives (the batch stopping its tasks) is handled as before."""
    import signal

    def gone() -> None:
        from ..base.outputs import remove_live

        remove_live()
        os._exit(128 + signal.SIGTERM)

    previous = signal.getsignal(signal.SIGTERM)

    def on_sigterm(signum, frame) -> None:
        if os.getppid() != parent:
            gone()
        if callable(previous):
            previous(signum, frame)
        else:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, on_sigterm)
    if not _death_signal(signal.SIGTERM):

        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(0.5)
            gone()

        threading.Thread(target=watch, name="datmo-parent-watch", daemon=True).start()
    if os.getppid() != parent:  # it died before the watch began
        gone()


def _death_signal(signum: int) -> bool:
    """Ask Linux to send `signum` to this process when its parent dies (prctl PR_SET_PDEATHSIG); False where
    that cannot be done."""
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(1, int(signum), 0, 0, 0) == 0  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return False


def _queued_task(task: Task) -> dict:
    queue = _SCANS[0]
    return run_task(task, scans=lambda d, n: queue.put((task.index, d, n)))


def _drain(queue, on_scans) -> None:
    import queue as queue_mod

    while True:
        try:
            i, d, n = queue.get_nowait()
        except (queue_mod.Empty, OSError, ValueError):
            return
        if on_scans:
            on_scans(i, d, n)
