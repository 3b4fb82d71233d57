"""The Dask worker plugin of `datmo run --scheduler` (its own module: it imports distributed at import)."""

from __future__ import annotations

from distributed import WorkerPlugin

from .batch import ensure_warm


class WarmUp(WorkerPlugin):
    """Load datmo's numba kernels once in each worker process, before its first task (and in workers that
    join later); registering it again on the same cluster does nothing."""

    name = "datmo-warm-up"
    idempotent = True

    def setup(self, worker) -> None:  # noqa: ANN001 - distributed.Worker
        ensure_warm()
