"""Threads that pay (make bench): `datmo run` and `datmo features` on the hall simulated at 37.5 Hz for 20,025
scans (benchmarks/hall_log: non-repeating), on 2 threads against 1 (`--threads`), in this process with a warm
cache, interleaved, best of REPEAT each.

Targets on two free cores: run >= 1.5x, features >= 1.6x. `run` on two threads perceives the next block on a
thread of its own beside the tracking and writing of the current one (RunStages.pipelined); `features` runs its
perception kernels on both. The load average is printed: a busy machine has no second core to give.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from benchmarks.common import best_of, print_lines
from benchmarks.hall_log import HALL_SCANS, simulated_hall

N = HALL_SCANS
REPEAT = 2
TARGETS = {"datmo run": 1.5, "datmo features": 1.6}


def main() -> None:
    from datmo_cli.passes.pipeline import process_file
    from datmo_cli.passes.stage_files import features_file
    from datmo_cli.passes.warm import warm_up
    from datmo_cli.perception import threads

    src = simulated_hall(N)
    warm_up()
    before = threads._DEFAULT
    lines = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp)
            commands = {
                "datmo run": lambda: process_file(src, out / "run.mcap", force=True),
                "datmo features": lambda: features_file(src, out / "features.mcap", force=True),
            }
            for name, fn in commands.items():
                best = {1: float("inf"), 2: float("inf")}
                for _ in range(REPEAT):
                    for n in (1, 2):
                        threads.set_default(n)
                        best[n] = min(best[n], best_of(fn, repeat=1))
                gain = best[1] / best[2]
                target = TARGETS[name]
                lines.append(
                    f"{name}: 1 thread {N / best[1]:,.0f} scans/s, 2 threads {N / best[2]:,.0f} scans/s: "
                    f"{gain:.2f}x (target >= {target:g}x on two free cores): {'met' if gain >= target else 'NOT met'}"
                )
    finally:
        threads.set_default(before)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines.append(f"simulated hall, {N:,} scans; {threads.available()} threads available; load average {load:.2f}")
    print_lines("Threads: 2 against 1", lines)


if __name__ == "__main__":
    main()
