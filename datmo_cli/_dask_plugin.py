"""The Dask worker plugin of `datmo run --scheduler` (its own module: it imports distributed at import)."""

from __future__ import annotations

from distributed import WorkerPlugin

from .batch.task import ensure_warm


class WarmUp(WorkerPlugin):
    """Load datmo's numba kernels once in each worker process, before its first task (and in workers that
    join later); registering it again on the same cluster does nothing."""

    name = "datmo-warm-up"
    idempotent = True

    def setup(self, worker) -> None:
        ensure_warm()


class IgnoreInterrupt(WorkerPlugin):
    """For the worker processes of a run's own local cluster: a terminal's Ctrl-C reaches every process of its
    group, and the batch (the client) stops their tasks itself, through its cancel Event."""

    name = "datmo-ignore-interrupt"
    idempotent = True

    def setup(self, worker) -> None:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
