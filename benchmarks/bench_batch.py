"""Batch throughput of `datmo run`: 8 sample-sized inputs (copies of sample_logs/hall.mcap, 300 scans each)
in this process (--jobs 1, kernels on one thread) and on a local Dask cluster of 1 and 2 worker processes
(--scheduler local:N, one thread each), and the scheduler's overhead per input against the local run.

Every figure is the wall time of the batch alone (prepare, tasks, manifest lines), best of REPEAT runs into
fresh output folders; starting the cluster and loading the kernels in its workers are timed apart.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row, print_lines, print_table

N_INPUTS = 8
REPEAT = 2
SAMPLE = Path(__file__).resolve().parent.parent / "sample_logs" / "hall.mcap"


def time_batch(inputs: list[str], executor, tmp: Path) -> tuple[float, int]:  # noqa: ANN001 - batch.Executor
    """Best (seconds, scans) of REPEAT runs of the batch into fresh folders."""
    from datmo_cli import batch

    best, scans = float("inf"), 0
    for _ in range(REPEAT):
        out = Path(tempfile.mkdtemp(dir=tmp))
        t0 = time.perf_counter()
        b = batch.prepare(inputs, str(out))
        records = batch.run(b, executor)
        seconds = time.perf_counter() - t0
        bad = [r["error"] for r in records if r["status"] != batch.DONE]
        if bad:
            raise RuntimeError(bad[0])
        best, scans = min(best, seconds), sum(r["scans"] for r in records)
    return best, scans


def main() -> None:
    from datmo_cli.batch import LocalExecutor, ensure_warm
    from datmo_cli.cluster import DaskExecutor

    ensure_warm()
    rows, started = [], {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        inputs = []
        for i in range(N_INPUTS):
            shutil.copy(SAMPLE, tmp / f"log{i}.mcap")
            inputs.append(str(tmp / f"log{i}.mcap"))
        import numba

        threads = numba.get_num_threads()
        numba.set_num_threads(1)          # one core, as one Dask worker process runs its kernels on one thread
        try:
            t_local, scans = time_batch(inputs, LocalExecutor(1), tmp)
        finally:
            numba.set_num_threads(threads)
        rows.append(Row("local --jobs 1", scans, t_local, f"{t_local / N_INPUTS:.3f} s per input"))
        t_dask = {}
        for n in (1, 2):
            t0 = time.perf_counter()
            ex = DaskExecutor(f"local:{n}")
            started[n] = time.perf_counter() - t0
            try:
                t_dask[n], scans = time_batch(inputs, ex, tmp)
            finally:
                ex.close()
            rows.append(Row(f"--scheduler local:{n}", scans, t_dask[n],
                            f"{t_dask[n] / N_INPUTS:.3f} s per input; cluster start + warm-up {started[n]:.1f} s"))
    speedup = t_dask[1] / t_dask[2]
    overhead = (t_dask[1] - t_local) / N_INPUTS
    print_table(f"Batch throughput: {N_INPUTS} inputs of {SAMPLE.name} ({scans // N_INPUTS} scans each), "
                f"{os.cpu_count()} cores", rows)
    print_lines("Batch targets", [
        f"2 workers / 1 worker throughput: {speedup:.2f}x (target >= 1.7x on 2 cores)",
        f"scheduler overhead per input (local:1 against --jobs 1): {overhead:+.3f} s (target < 0.2 s)",
    ])


if __name__ == "__main__":
    main()
