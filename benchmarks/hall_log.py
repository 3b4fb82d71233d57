"""Non-repeating bench logs: the simulated hall scene at an LMS200's 37.5 Hz (361 beams, 0.5°), /scan only.

A tiled log repeats the same scans, which flatters both speed and compression; these logs do not repeat. Each is
simulated once (a fixed seed, so the same file every time) and kept in the system's temporary folder.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from datmo_cli.logs import mcapio

CACHE = Path(tempfile.gettempdir()) / "datmo-bench"
RATE_HZ = 37.5
HALL_SCANS = 20_025  # 534 s at 37.5 Hz


def simulated_hall(n_scans: int = HALL_SCANS) -> Path:
    """The hall scene simulated for `n_scans` scans at 37.5 Hz (at most 3,600 s), its /scan alone in an MCAP."""
    path = CACHE / f"hall-sim-{n_scans}.mcap"
    if path.exists():
        return path
    CACHE.mkdir(parents=True, exist_ok=True)
    full = CACHE / f"hall-sim-{n_scans}-with-truth.mcap"
    duration = n_scans / RATE_HZ
    cmd = [sys.executable, "-m", "datmo_cli", "simulate", "--scene", "hall", "--rate", str(RATE_HZ)]
    cmd += ["--duration", f"{duration:.6f}", "--seed", "0", "-o", str(full), "--force"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    run = mcapio.read_run(full)
    tmp = path.with_suffix(".tmp")
    with mcapio.LogWriter(tmp, force=True) as w:
        w.write_scans(run)
    tmp.rename(path)
    full.unlink()
    return path


if __name__ == "__main__":
    for n in sys.argv[1:] or [str(HALL_SCANS)]:
        print(simulated_hall(int(n)))
