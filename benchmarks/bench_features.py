"""Segmentation and feature extraction speed on the 361-beam hall log (one core, after warm-up), beside the
plain MCAP read speed of the same file, and the start-up time of a second `datmo features` run (the numba
cache: no recompilation)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.log import mcapio
from datmo_cli.log.scan import ScanRun
from datmo_cli.perception.features import derive_features, extract_run, segment_run

ROOT = Path(__file__).resolve().parent.parent
HALL = ROOT / "sample_logs" / "hall.mcap"
N_SCANS = 20_000


def tiled(run: ScanRun, n: int) -> ScanRun:
    """`run`'s scans repeated to `n` scans with increasing stamps (stable timings on a small log)."""
    reps = -(-n // len(run))
    ranges = np.tile(run.ranges, (reps, 1))[:n]
    period = int(np.median(np.diff(run.stamps)))
    return ScanRun(run.stamps[0] + np.arange(n, dtype=np.int64) * period, ranges, run.geometry)


def mcap_iterate(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(topics=[mcapio.TOPIC_SCAN]))


def startup_seconds(cache_dir: str | None) -> float:
    """Wall time of a fresh process that imports datmo and extracts the features of a 10-scan run."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = ("from datmo_cli.log import mcapio; from datmo_cli.perception.features import extract_run; "
            f"run = mcapio.read_run({str(HALL)!r}); extract_run(run.slice(0, 10))")
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, env=env)
    return time.perf_counter() - t0


def main() -> None:
    small = mcapio.read_run(HALL)
    run = tiled(small, N_SCANS)
    extract_run(small)   # warm-up: compile or load the kernels
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hall-20k.mcap"
        with mcapio.LogWriter(path) as w:
            w.write_scans(run)
        t_iter = best_of(lambda: mcap_iterate(path))
        t_read = best_of(lambda: mcapio.read_run(path))
        with tempfile.TemporaryDirectory() as cold:
            first = startup_seconds(cold)
            second = startup_seconds(cold)
    t_seg = best_of(lambda: segment_run(run))
    t_feat = best_of(lambda: extract_run(run, landmarks=False))
    t_land = best_of(lambda: extract_run(run))
    t_derive = best_of(lambda: derive_features(run), repeat=1)
    f = extract_run(small).counts()
    rows = [
        Row("mcap iter_messages (no decoding)", N_SCANS, t_iter, "baseline: plain MCAP read"),
        Row("datmo read_run (decode to arrays)", N_SCANS, t_read),
        Row("segmentation", N_SCANS, t_seg, "target >= 200,000 scans/s"),
        Row("segmentation + lines, circles, blobs", N_SCANS, t_feat, "target >= 20,000 scans/s"),
        Row("  + landmarks (full feature extraction)", N_SCANS, t_land, "target >= 20,000 scans/s"),
        Row("  + CDR messages and markers (datmo features)", N_SCANS, t_derive, "all channels encoded"),
    ]
    print_table(f"Segmentation and features, hall log tiled to {N_SCANS:,} scans x 361 beams", rows)
    print_lines("Feature extraction figures", [
        f"segmentation: {N_SCANS / t_seg:,.0f} scans/s (target >= 200,000)",
        f"segmentation + full feature extraction: {N_SCANS / t_land:,.0f} scans/s (target >= 20,000)",
        f"per scan on the hall log: {f['segments']:.1f} segments, {f['lines']:.1f} lines, {f['circles']:.1f} circles, "
        f"{f['blobs']:.1f} blobs",
        f"start-up of datmo features on 10 scans: {first:.2f} s with an empty numba cache, {second:.2f} s on the "
        "second run (cache hit, no recompilation)",
    ])


if __name__ == "__main__":
    main()
