"""The leg detector's cost (make bench): segmentation + lines, circles and blobs per scan, as datmo did it
before the detector (the paper's rule, the circle well-posedness tests off: datmo's first perception), with
the well-posed circle rule, and with the leg detector (the shipped model) on top; on the hall log tiled to
5,000 scans, the CARMEN csail, intel and freiburg-079 logs, and a legtracker bag (768 beams). One core,
after warm-up. Target: the detector costs at most 25 % more per scan than the perception before it.

Against BASELINE (the commit speed round 3 started from; issue 34): perception with the leg detector on (the
shipped model, one thread, no landmarks) on csail, intel and freiburg-079, µs per scan of today's code beside
BASELINE's measured in the same run (BASELINE's package exported once from git, each version timed in its own
subprocess, alternately, best of several passes per 64-scan block; see bench_perception_cores), the ratio
against LEG_TARGETS. With DATMO_BENCH_PEER=path.json ({"csail": 55, ...}: a peer's µs/scan per log, e.g.
obstacle_detector's, measured apart: the peer is not part of the project) each log's datmo/peer ratio too.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from benchmarks.bench_perception import HALL, one_core, tiled
from benchmarks.bench_perception_cores import LOGS, ROUNDS, log_arrays, old_tree, time_version
from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanRun
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.params import FeatureParams

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"
TARGET = 1.25
BASELINE = "a932713"  # issue 34's starting commit
LEG_TARGETS = {"csail": 0.38, "intel": 0.42, "freiburg-079": 0.39}  # x BASELINE's µs/scan, legs on
PEER_ENV = "DATMO_BENCH_PEER"
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
    from datmo_cli.logs.importers import import_log

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


def peer_timings() -> tuple[dict[str, float], str]:
    """The peer's µs/scan per log from the file DATMO_BENCH_PEER names: ({}, "") when unset, ({}, why) when
    the file is not a JSON object of positive numbers."""
    path = os.environ.get(PEER_ENV)
    if not path:
        return {}, ""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        return {}, f"{PEER_ENV}={path}: unreadable ({exc.__class__.__name__}: {exc})"
    if not isinstance(data, dict) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and v > 0 for v in data.values()
    ):
        return {}, f"{PEER_ENV}={path}: not a JSON object of positive µs/scan per log"
    return {str(k): float(v) for k, v in data.items()}, ""


def against_baseline() -> list[str]:
    """Perception with the leg detector, today's code beside BASELINE's in the same run, per log: µs/scan (wall
    and CPU), the ratio against LEG_TARGETS and, with a peer timings file, datmo/peer."""
    paths, why = log_arrays()
    root = None
    if paths:
        root, why = old_tree(BASELINE)
    if root is None:
        return [f"skipped: {why}"]
    best: dict[str, dict[str, list[float]]] = {"old": {}, "new": {}}
    for _ in range(ROUNDS):  # alternating subprocesses, best of each
        for key, tree in (("old", root), ("new", ROOT)):
            for name, got in time_version(tree, paths, 1, True).items():
                prev = best[key].get(name, [float("inf")] * 2)
                best[key][name] = [min(a, b) for a, b in zip(prev, got, strict=True)]
    peer, why_not = peer_timings()
    lines = [
        f"µs/scan, segmentation + lines, circles, blobs + the shipped leg detector, 1 thread; best of {ROUNDS} "
        f"alternating rounds; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (CPU time: the "
        "like-for-like figure when other processes share the cores)"
    ]
    for name in LOGS:
        (o, oc), (n, nc) = best["old"][name], best["new"][name]
        target = LEG_TARGETS[name]
        line = (
            f"{name:>13}: {BASELINE} {o:6.1f} (CPU {oc:6.1f})   today {n:6.1f} (CPU {nc:6.1f}): {n / o:.2f}x "
            f"(CPU {nc / oc:.2f}x), target <= {target:.2f}x: {'met' if nc / oc <= target else 'NOT met'}"
        )
        if name in peer:
            line += f"   datmo/peer {n / peer[name]:.2f}x ({BASELINE}: {o / peer[name]:.2f}x; peer {peer[name]:g})"
        lines.append(line)
    if why_not:
        lines.append(why_not)
    elif not peer:
        lines.append(f"no peer figures ({PEER_ENV}=path.json of µs/scan per log, e.g. obstacle_detector's)")
    return lines


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
    print_lines(f"Perception with the leg detector against {BASELINE} (issue 34)", against_baseline())


if __name__ == "__main__":
    main()
