"""Log I/O speed: writing and decoding a 20,000-scan, 361-beam run beside mcap's bare iteration."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanGeometry, ScanRun

N_SCANS = 20_000


def synthetic_run(n: int = N_SCANS) -> ScanRun:
    """A room-like run: smooth ranges with noise and a few no-returns, quantised to mm like an LMS200."""
    rng = np.random.default_rng(0)
    g = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.183, 0.0, 0.2, "laser")
    base = 3 + 2 * np.abs(np.sin(g.angles() * 2))
    ranges = np.round(base + rng.normal(0, 0.01, (n, 361)), 3).astype(np.float32)
    ranges[rng.random(ranges.shape) < 0.01] = np.nan
    return ScanRun(1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 200_000_000, ranges, g)


def mcap_iterate(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(topics=[mcapio.TOPIC_SCAN]))


def main() -> None:
    run = synthetic_run()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"

        def write() -> None:
            with mcapio.LogWriter(path, force=True) as w:
                w.write_scans(run)

        t_write = best_of(write)
        t_iter = best_of(lambda: mcap_iterate(path))
        t_read = best_of(lambda: mcapio.read_run(path))
        size = path.stat().st_size
    rows = [
        Row("mcap iter_messages (no decoding)", N_SCANS, t_iter, "baseline"),
        Row("datmo read_run (decode to arrays)", N_SCANS, t_read, f"{t_iter / t_read:.2f}x the baseline's speed"),
        Row(
            "datmo write (encode + zstd MCAP)",
            N_SCANS,
            t_write,
            f"{t_write / (N_SCANS / 10_000):.2f} s per 10,000 scans",
        ),
    ]
    print_table("Log I/O, 20,000 scans x 361 beams", rows)
    print_lines(
        "Log I/O targets",
        [
            f"decode / bare-iteration speed ratio: {t_iter / t_read:.2f} (target >= 0.80)",
            f"write: {t_write / (N_SCANS / 10_000):.3f} s per 10,000 scans (target < 1 s)",
            f"file size: {size / 1e6:.1f} MB ({size / N_SCANS:.0f} bytes/scan)",
        ],
    )


if __name__ == "__main__":
    main()
