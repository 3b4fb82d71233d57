"""The Dask worker plugin of `datmo run --scheduler` (its own module: it imports distributed at import)."""

from __future__ import annotations

from distributed import WorkerPlugin


class WarmUp(WorkerPlugin):
    """Load datmo's numba kernels once in each worker process, before its first task (and in workers that
    join later); registering it again on the same cluster does nothing."""

    name = "datmo-warm-up"
    idempotent = True

    def setup(self, worker) -> None:
        from ..passes.warm import warm_up

        warm_up()


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


class LocalWorker(WorkerPlugin):
    """For the worker processes of a run's own local cluster: no HTTP server (it serves no route, the run's
    configuration gives none; this closes its port too), and what the worker logs (errors only: the run
    silences the rest) goes to stderr escaped and rate-limited, as the client's own (progress.route_logs)."""

    name = "datmo-local-worker"
    idempotent = True

    def setup(self, worker) -> None:
        from ..base.progress import Limited, route_logs

        server = getattr(worker, "http_server", None)
        if server is not None:
            server.stop()
        route_logs(("distributed",), Limited("datmo: dask worker", multiline=True), level=40)
