"""`datmo run --scheduler`: a batch's tasks on a Dask distributed cluster.

One task per input (`batch.task.run_task` on a worker; the input and output paths are resolved for a shared
filesystem or are fsspec URLs). Each worker process loads datmo's numba kernels once (a worker plugin
calls `warm.warm_up`), not per task. A task that raises an unexpected error is retried by Dask
(`retries`); a task whose worker dies is rescheduled on another worker by the scheduler, and resubmitted
by the client up to `retries` times if the scheduler gives it up (KilledWorker). Ctrl-C sets a cluster-
wide Event that running tasks poll as their scans go by: they stop, drop their partial output and return.
At most `window` tasks are in the scheduler at a time, so a batch of a million inputs does not hold a
million futures.
"""

from __future__ import annotations

import os
import re
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from ..base.errors import DatmoError
from ..base.extras import require
from .executors import Executor
from .manifest import CANCELLED
from .task import Task, failed, run_task

CANCEL_POLL_S = 0.5
CANCEL_GRACE_S = 10.0
CONNECT_TIMEOUT = "15s"


def cores() -> int:
    """The cores this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def parse_local(address: str) -> int | None:
    """N for `local[:N]` (default: the cores here), None for a scheduler address. N is at most the cores here:
    each worker is a process running one input at a time, and more would only share the cores (and memory)."""
    if address != "local" and not address.startswith("local:"):
        return None
    n = address.partition(":")[2]
    if not n:
        return cores()
    if not re.fullmatch("[0-9]{1,9}", n) or int(n) < 1:  # ASCII digits only: `²` passes str.isdigit
        raise DatmoError(f"--scheduler {address}: expected local or local:N with N >= 1 workers")
    if int(n) > cores():
        raise DatmoError(f"--scheduler {address}: at most local:{cores()} here (one worker process per core)")
    return int(n)


def local_security(address: str):
    """A temporary TLS certificate for a run's own local cluster (distributed's Security.temporary, held in
    memory only): the scheduler and the workers then talk TLS and accept only peers holding it, so another
    user of this machine cannot connect to them and run code as the user running datmo."""
    try:
        from distributed.security import Security

        return Security.temporary()
    except ImportError:
        from ..base.extras import MissingExtraError

        raise MissingExtraError(
            f"--scheduler {address}: the local cluster's TLS certificate needs cryptography "
            "(part of the dask extra), which is not installed: pip install cryptography"
        ) from None


def client_security(address: str):
    """The TLS settings of the Dask configuration for a `tls://` scheduler (None for another address);
    DatmoError in one line when the configuration holds no usable certificate."""
    if not address.startswith("tls://"):
        return None
    from distributed.security import Security

    how = (
        "set distributed.comm.tls.ca-file, distributed.comm.tls.client.cert and distributed.comm.tls.client.key "
        "in the Dask configuration, e.g. DASK_DISTRIBUTED__COMM__TLS__CA_FILE=ca.pem (see docs/batch.md, "
        "Security of the cluster)"
    )
    try:
        security = Security()
        args = security.get_connection_args("client")
    except (OSError, ValueError, TypeError) as exc:
        raise DatmoError(
            f"--scheduler {address}: cannot load the TLS certificate of the Dask configuration ({exc}); {how}"
        ) from None
    if args.get("ssl_context") is None:
        raise DatmoError(f"--scheduler {address}: a tls:// scheduler needs this client's certificate: {how}")
    return security


def _worker_task(task: Task, cancel_event: str) -> dict:
    """What a worker runs for one input: warm (once per process), then run_task polling the cancel Event."""
    from distributed import Event

    from ..passes.warm import warm_up
    from ..perception.threads import set_default

    warm_up()
    set_default(task.threads or 1)  # Dask runs one task per worker thread: perception on one thread unless told
    event = Event(cancel_event)
    last: list[Any] = [0.0, False]  # when polled, and what the event said

    def cancelled() -> bool:
        now = time.monotonic()
        if not last[1] and now - last[0] >= CANCEL_POLL_S:
            last[0], last[1] = now, bool(event.is_set())
        return last[1]

    return run_task(task, cancelled=cancelled, raise_unexpected=True)


class DaskExecutor(Executor):
    """A batch's tasks on a running Dask scheduler (`tcp://host:8786`) or on a local cluster (`local[:N]`,
    N worker processes of one thread started for the run)."""

    def __init__(self, address: str, *, retries: int = 2, window: int | None = None) -> None:
        distributed = require("distributed", for_="--scheduler")
        dask = require("dask", for_="--scheduler")

        self.address = address
        self.retries = retries
        self.cluster = None
        n = parse_local(address)
        try:
            if n is not None:
                import logging

                from ..passes.warm import warm_up

                warm_up()  # compile (or load) the kernels here once, so N workers do not compile them at once

                # the workers' statistical profiler samples every thread's stack 100 times a second: off for a
                # run's own cluster (pipeline code holds the GIL between kernels); and one numba thread per worker
                # process, as there is one worker per core. The nanny sets that variable in this process's own
                # environment before it spawns a worker: it is put back after, or this process's numba would
                # refuse to run kernels on its threads (NUMBA_NUM_THREADS changed after they were launched)
                security = local_security(address)  # TLS: no other user of this machine can connect
                self._quiet_dask()
                own_threads = os.environ.get("NUMBA_NUM_THREADS")
                try:
                    with dask.config.set(
                        {
                            "distributed.scheduler.allowed-failures": retries,
                            "distributed.worker.profile.enabled": False,
                            "distributed.nanny.pre-spawn-environ.NUMBA_NUM_THREADS": 1,
                            # no HTTP endpoint (/info, /json, /metrics, call stacks, logs: served without
                            # authentication) on the scheduler or the workers; their servers are stopped below
                            "distributed.scheduler.http.routes": [],
                            "distributed.worker.http.routes": [],
                        }
                    ):
                        self.cluster = distributed.LocalCluster(
                            n_workers=n,
                            threads_per_worker=1,
                            processes=True,
                            host="127.0.0.1",
                            protocol="tls://",
                            security=security,
                            dashboard_address=None,
                            # a free loopback port for the scheduler's (empty) HTTP server, not 8787 and a
                            # warning when another cluster has it
                            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                            silence_logs=logging.ERROR,
                        )
                    self.cluster.scheduler.http_server.stop()
                finally:
                    if own_threads is None:
                        os.environ.pop("NUMBA_NUM_THREADS", None)
                    else:
                        os.environ["NUMBA_NUM_THREADS"] = own_threads
                self.client = distributed.Client(self.cluster, security=security)
            else:
                self.client = distributed.Client(address, timeout=CONNECT_TIMEOUT, security=client_security(address))
        except (OSError, TimeoutError, ValueError) as exc:
            self.close()
            raise DatmoError(f"--scheduler {address}: cannot reach the Dask scheduler ({exc})") from None
        from .dask_plugin import IgnoreInterrupt, LocalWorker, WarmUp

        if self.cluster is not None:
            self.client.register_plugin(IgnoreInterrupt(), name=IgnoreInterrupt.name)
            self.client.register_plugin(LocalWorker(), name=LocalWorker.name)
        self.client.register_plugin(WarmUp(), name=WarmUp.name)  # returns once every worker has loaded them
        threads = sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values())
        self.workers = max(threads, 1)
        self.where = (
            f"a local Dask cluster of {n} worker{'s' if n > 1 else ''}"
            if n is not None
            else f"the Dask scheduler {address} ({self.workers} worker threads)"
        )
        self.window = window or max(64, 4 * self.workers)

    def run(
        self,
        tasks: list[Task],
        on_record: Callable[[dict], None],
        on_scans: Callable[[int, int, int], None] | None = None,
    ) -> None:
        from distributed import KilledWorker, as_completed

        if not tasks:
            return
        token = uuid.uuid4().hex[:12]
        cancel_event = f"datmo-cancel-{token}"
        queue = deque(tasks)
        live: dict[str, tuple] = {}  # key -> (future, task)
        attempts: dict[int, int] = {}
        stream = as_completed()

        def submit(t: Task) -> None:
            attempts[t.index] = attempts.get(t.index, 0) + 1
            key = f"datmo-run-{token}-{t.index}-{attempts[t.index]}"
            fut = self.client.submit(_worker_task, t, cancel_event, key=key, retries=self.retries, pure=False)
            live[fut.key] = (fut, t)
            stream.add(fut)

        def collect(fut) -> None:
            t = live.pop(fut.key)[1]
            try:
                rec = fut.result()
            except KilledWorker as exc:
                if attempts[t.index] <= self.retries:
                    submit(t)
                    return
                rec = failed(t, f"worker died {attempts[t.index]} times running it ({exc})")
            except Exception as exc:  # Dask retried it `retries` times
                rec = failed(t, f"failed: {type(exc).__name__}: {exc}")
            fut.release()
            on_record(rec)

        for _ in range(min(self.window, len(queue))):
            submit(queue.popleft())
        with _interrupt_flag() as stop:  # Ctrl-C sets a flag: no KeyboardInterrupt inside distributed's calls
            while live and not stop:
                done = stream.next_batch(block=False)
                if not done:
                    time.sleep(0.02)
                for fut in done:
                    collect(fut)
                    while queue and len(live) < self.window:
                        submit(queue.popleft())
            if stop:
                self._cancel(cancel_event, live, on_record)
                raise KeyboardInterrupt

    def _cancel(self, cancel_event: str, live: dict[str, tuple], on_record: Callable[[dict], None]) -> None:
        """Ctrl-C: set the Event the running tasks poll; record those that finish within CANCEL_GRACE_S (their
        outputs are complete), drop the others, and close the client (and the run's own cluster)."""
        from distributed import Event

        try:
            Event(cancel_event, client=self.client).set()
            deadline = time.monotonic() + CANCEL_GRACE_S
            for fut, _ in list(live.values()):
                try:
                    rec = fut.result(timeout=max(0.1, deadline - time.monotonic()))
                except Exception:
                    continue
                if rec.get("status") != CANCELLED:
                    on_record(rec)
            self.client.cancel([f for f, _ in live.values()], force=True)
        finally:
            self.close()

    def _quiet_dask(self) -> None:
        """What the run's own cluster (its scheduler and nannies live in this process) logs goes to stderr
        escaped and rate-limited (progress.route_logs), until close()."""
        from ..base.progress import Limited, route_logs

        self._dask_log = Limited("datmo: dask", multiline=True)
        self._restore_log: Callable[[], None] | None = route_logs(("distributed",), self._dask_log, level=40)

    def close(self) -> None:
        for thing in (getattr(self, "client", None), self.cluster):
            if thing is not None:
                try:
                    thing.close()
                except Exception:
                    pass
        self.cluster = None
        restore = getattr(self, "_restore_log", None)
        if restore is not None:
            self._restore_log = None
            restore()
            self._dask_log.close()


@contextmanager
def _interrupt_flag() -> Iterator[list[int]]:
    """A list that gets an item when Ctrl-C (SIGINT) arrives inside the block (main thread only), instead of
    a KeyboardInterrupt."""
    import signal
    import threading

    stop: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = signal.signal(signal.SIGINT, lambda sig, frame: stop.append(sig))
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)
