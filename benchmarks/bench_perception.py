"""Perception speed (make bench): segmentation, features, landmarks and `datmo features`' encoding on the
361-beam hall log tiled to 20,000 scans, one core, after warm-up, beside the plain MCAP read speed of the
same file (targets: segmentation >= 200,000 scans/s, segmentation + full feature extraction >= 20,000
scans/s); the start-up time of a fresh process that extracts the features of 10 scans, with a cold
numba cache and on the second run (cache hit, no recompilation); and the paper's-rule perception (segmentation,
lines, circles, blobs; no leg detector, no landmarks) on the CARMEN csail, intel and freiburg-079 logs beside
the code of START, the commit the third speed round started from, measured in the same run (issue 34's target:
about 0.4x of START's time; the leg detector's share is bench_legs' and bench_perception_cores')."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanRun
from datmo_cli.passes.stages import derive_features
from datmo_cli.perception.features import extract_run, segment_run

ROOT = Path(__file__).resolve().parent.parent
HALL = ROOT / "sample_logs" / "hall.mcap"
CARMEN = ROOT.parent / "shared" / "data" / "carmen"
CARMEN_LOGS = ("csail", "intel", "freiburg-079")
CACHE = Path(tempfile.gettempdir()) / "datmo-bench"
START = "a932713"  # the code the third speed round (issue 34) started from
ROUNDS = 3  # START's and this code's child processes, interleaved; the best of each
N_SCANS = 20_000
SEGMENT_TARGET = 200_000  # scans/s
FEATURES_TARGET = 20_000  # scans/s, segmentation + lines, circles, blobs and landmarks

# A fresh interpreter: import the perception code and extract the features of a 10-scan run.
STARTUP_CODE = """
import numpy as np
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.perception.features import extract_run
g = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")
a = g.angles()
ranges = np.tile(np.minimum(2.0 / np.maximum(np.cos(a - 0.3), 1e-3), 7.5), (10, 1))
f = extract_run(ScanRun(np.arange(10, dtype=np.int64) * 200_000_000, ranges, g))
assert len(f.lines) >= 10
"""


def tiled(run: ScanRun, n: int = N_SCANS) -> ScanRun:
    """`run`'s scans repeated up to `n` scans, stamps continuing at the run's scan period."""
    reps = -(-n // len(run))
    period = int(np.median(np.diff(run.stamps)))
    stamps = run.stamps[0] + np.arange(n, dtype=np.int64) * period
    return ScanRun(stamps, np.tile(run.ranges, (reps, 1))[:n], run.geometry)


def mcap_iterate(path: Path) -> int:
    """Plain MCAP read: the mcap package's reader iterating the scan messages (no decoding)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(topics=[mcapio.TOPIC_SCAN]))


def startup_seconds(cache_dir: str | None = None) -> float:
    """Wall time of `python -c STARTUP_CODE` (NUMBA_CACHE_DIR set to `cache_dir` when given)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", STARTUP_CODE], check=True, env=env, cwd=ROOT)
    return time.perf_counter() - t0


def one_core() -> set[int] | None:
    """Pin this process to one CPU and the perception kernels to one thread (their default is all cores;
    see bench_perception_cores for the figures on several); this keeps numpy to one core too."""
    from datmo_cli.perception.threads import set_default

    set_default(1)
    if not hasattr(os, "sched_getaffinity"):
        return None
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(before)})
    return before


# A child process timing the paper's-rule perception (no leg detector, no landmarks) on each CARMEN log saved
# as .npz in argv[1]: CPU time of the one thread (the machine may be shared), best of argv[2] calls, µs/scan.
CARMEN_CODE = """
import json, sys, time
import numpy as np
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.params import FeatureParams
from datmo_cli.perception.threads import set_default
set_default(1)
p = FeatureParams(leg_model="paper")
out = {}
for name in sys.argv[3:]:
    d = np.load(f"{sys.argv[1]}/{name}.npz")
    a = d["geometry"]
    g = ScanGeometry(a[0], a[1], int(a[2]), a[3], a[4], a[5], a[6], str(d["frame_id"]))
    run = ScanRun(d["stamps"], d["ranges"], g)
    extract_run(ScanRun(run.stamps[:20], run.ranges[:20], g), p, landmarks=False)
    best = float("inf")
    for _ in range(int(sys.argv[2])):
        t0 = time.thread_time()
        extract_run(run, p, landmarks=False)
        best = min(best, time.thread_time() - t0)
    out[name] = 1e6 * best / len(run)
print(json.dumps(out))
"""


def start_tree() -> Path | None:
    """A git worktree of START beside the bench logs (made once), or None without git."""
    tree = CACHE / f"datmo-{START}"
    if (tree / "datmo_cli").exists():
        return tree
    done = subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(tree), START], capture_output=True
    )
    return tree if done.returncode == 0 else None


def carmen_npz() -> list[str]:
    """The CARMEN logs present, each imported once into CACHE as .npz (stamps, ranges, geometry)."""
    from datmo_cli.logs.importers import import_log

    names = []
    for name in CARMEN_LOGS:
        src, dst = CARMEN / f"{name}-corrected.log.gz", CACHE / f"carmen-{name}.npz"
        if not dst.exists() and src.exists():
            CACHE.mkdir(parents=True, exist_ok=True)
            run = import_log(src).run
            g = run.geometry
            geometry = [g.angle_min, g.angle_increment, g.n_beams, g.range_min, g.range_max]
            geometry += [g.time_increment, g.scan_time]
            np.savez(dst, stamps=run.stamps, ranges=run.ranges, geometry=geometry, frame_id=g.frame_id)
        if dst.exists():
            names.append(f"carmen-{name}")
    return names


def carmen_us_per_scan(tree: Path, names: list[str], repeat: int = 3) -> dict[str, float] | None:
    """µs/scan (CPU, one thread) of `tree`'s perception on each of `names` (see CARMEN_CODE), in a fresh
    process with `tree` first on the path; None when it cannot run here."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [sys.executable, "-c", CARMEN_CODE, str(CACHE), str(repeat), *names]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tree)
    return json.loads(done.stdout.strip().splitlines()[-1]) if done.returncode == 0 else None


def carmen_vs_start() -> list[str]:
    """The paper's-rule perception on the CARMEN logs, this code beside START's, interleaved in ROUNDS pairs of
    child processes (the best of each): one line a log."""
    names = carmen_npz()
    if not names:
        return [f"CARMEN logs absent under {CARMEN}: not measured"]
    tree = start_tree()
    if tree is None:
        return [f"no git worktree of {START} could be made: the CARMEN figures are not measured"]
    old: dict[str, float] = {}
    new: dict[str, float] = {}
    for _ in range(ROUNDS):
        for tree_, best in ((tree, old), (ROOT, new)):
            got = carmen_us_per_scan(tree_, names)
            if got is None:
                return [f"the perception of {tree_} did not run on the CARMEN logs"]
            for k, v in got.items():
                best[k] = min(best.get(k, v), v)
    return [
        f"{k.removeprefix('carmen-')}: {new[k]:.1f} µs/scan, {START}'s {old[k]:.1f} in the same run: "
        f"{new[k] / old[k]:.2f}x (paper's rule, no leg detector; target about 0.4x)"
        for k in names
    ]


def main() -> None:
    small = mcapio.read_run(HALL)
    run = tiled(small)
    n = len(run)
    # warm-up: load (or compile) every kernel once
    segment_run(small)
    derive_features(small)
    with tempfile.TemporaryDirectory() as cold:
        t_cold = startup_seconds(cold)
        t_second_fresh_dir = startup_seconds(cold)
    startup_seconds()  # the project's own numba cache: filled by the first run if it was empty
    t_second = startup_seconds()
    saved = one_core()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "hall-tiled.mcap"
            with mcapio.LogWriter(path) as w:
                w.write_scans(run)
            t_iter = best_of(lambda: mcap_iterate(path))
            t_read = best_of(lambda: mcapio.read_run(path))
        t_seg = best_of(lambda: segment_run(run))
        t_feat = best_of(lambda: extract_run(run, landmarks=False))
        t_land = best_of(lambda: extract_run(run))
        t_derive = best_of(lambda: derive_features(run), repeat=2)
    finally:
        if saved is not None:
            os.sched_setaffinity(0, saved)
    f = extract_run(small)
    c = f.counts()
    rows = [
        Row("mcap iter_messages of the same log (no decoding)", n, t_iter, "baseline: plain MCAP read"),
        Row("datmo read_run (decode to arrays)", n, t_read, f"{t_iter / t_read:.2f}x the baseline's speed"),
        Row("segmentation (segment_run)", n, t_seg, f"target >= {SEGMENT_TARGET:,} scans/s"),
        Row("segmentation + lines, circles, blobs", n, t_feat, "extract_run(landmarks=False)"),
        Row("  + landmarks (full feature extraction)", n, t_land, f"target >= {FEATURES_TARGET:,} scans/s"),
        Row("  + CDR encoding of all channels", n, t_derive, "derive_features (4 channels)"),
    ]
    print_table(f"Perception, hall log tiled to {n:,} scans x {small.geometry.n_beams} beams, one core", rows)

    def verdict(rate: float, target: float) -> str:
        return "met" if rate >= target else "NOT met"

    print_lines(
        "Perception targets",
        [
            f"segmentation: {n / t_seg:,.0f} scans/s, {1e6 * t_seg / n:.1f} µs/scan "
            f"(target >= {SEGMENT_TARGET:,}: {verdict(n / t_seg, SEGMENT_TARGET)})",
            f"segmentation + full feature extraction (landmarks included): {n / t_land:,.0f} scans/s, "
            f"{1e6 * t_land / n:.1f} µs/scan (target >= {FEATURES_TARGET:,}: {verdict(n / t_land, FEATURES_TARGET)})",
            f"without landmarks: {n / t_feat:,.0f} scans/s; with all channels encoded (datmo features): "
            f"{n / t_derive:,.0f} scans/s; plain MCAP read of the same log: {n / t_iter:,.0f} scans/s",
            f"per hall scan: {c['segments']:.1f} segments, {c['lines']:.1f} lines, {c['circles']:.1f} circles, "
            f"{c['blobs']:.1f} blobs; {len(f.landmarks.final())} landmarks at the end",
            f"start-up, fresh process importing datmo_cli.perception.features and extracting 10 scans: "
            f"{t_second:.2f} s on a second run (numba cache hit, no recompilation)",
            f"  with an empty NUMBA_CACHE_DIR: {t_cold:.2f} s first (compiles), {t_second_fresh_dir:.2f} s second",
        ],
    )
    print_lines(f"Perception on CARMEN logs (one thread, CPU time), beside {START}", carmen_vs_start())


if __name__ == "__main__":
    main()
