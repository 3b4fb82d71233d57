"""The leg detector's cost (make bench): segmentation + lines, circles and blobs per scan, as datmo did it
before the detector (the paper's rule, the circle well-posedness tests off: datmo's first perception), with
the well-posed circle rule, and with the leg detector (the shipped model) on top; on the hall log tiled to
5,000 scans, the CARMEN csail, intel and freiburg-079 logs, and a legtracker bag (768 beams). One core,
after warm-up. Target: the detector costs at most 25 % more per scan than the perception before it.
"""

from __future__ import annotations

import os
from pathlib import Path

from benchmarks.bench_perception import HALL, one_core, tiled
from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.log import mcapio
from datmo_cli.log.scan import ScanRun
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.params import FeatureParams

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"
TARGET = 1.25
BEFORE = FeatureParams(leg_model="paper").replace(
    circle_min_coverage=0, circle_residual_ratio=0, circle_radius_margin=0, circle_lines_ratio=0
)
CONFIGS = (
    ("before the detector (the paper's rule)", BEFORE),
    ("well-posed circles, paper's legs", FeatureParams(leg_model="paper")),
    ("  + leg detector (shipped model)", FeatureParams()),
)


def logs() -> list[tuple[str, object]]:
    """(name, ScanRun) of each log measured: the hall tiled to 5,000 scans, then the real logs present."""
    from datmo_cli.log.importers import import_log

    out = [("hall x5,000", tiled(mcapio.read_run(HALL), 5000))]
    for name in ("csail", "intel", "freiburg-079"):
        path = SHARED / "carmen" / f"{name}-corrected.log.gz"
        if path.exists():
            out.append((name, import_log(path).run))
    bag = SHARED / "legtracker" / "positive_4_extracted.bag"
    if bag.exists():
        run = import_log(bag, "/training_scan").run
        out.append(("positive_4 (768 beams) x10", tiled(run, 10 * len(run))))
    return out


def main() -> None:
    runs = logs()
    for _, run in runs:  # warm-up: load (or compile) every kernel
        for _, p in CONFIGS:
            extract_run(ScanRun(run.stamps[:20], run.ranges[:20], run.geometry), p, landmarks=False)
    saved = one_core()
    rows, verdicts = [], []
    try:
        for name, run in runs:
            times = [best_of(lambda p=p, run=run: extract_run(run, p, landmarks=False)) for _, p in CONFIGS]
            n = len(run)
            for (label, _), t in zip(CONFIGS, times, strict=True):
                rows.append(Row(f"{name}: {label}", n, t, f"{t / times[0]:.2f}x before"))
            ratio = times[2] / times[0]
            verdicts.append(
                f"{name}: {1e6 * times[0] / n:.1f} -> {1e6 * times[2] / n:.1f} µs/scan with the detector, "
                f"{ratio:.2f}x (target <= {TARGET:.2f}x: {'met' if ratio <= TARGET else 'NOT met'})"
            )
    finally:
        if saved is not None:
            os.sched_setaffinity(0, saved)
    print_table("Leg detector cost: segmentation + lines, circles, blobs (+ legs), one core", rows)
    print_lines("Leg detector cost targets", verdicts)


if __name__ == "__main__":
    main()
