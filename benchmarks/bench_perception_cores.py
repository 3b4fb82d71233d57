"""Perception against the code of an older commit (OLD), and on several cores (make bench).

Against OLD: segmentation + lines, circles and blobs (extract_run without landmarks; the paper's leg rule, as
OLD had no leg detector) on the CARMEN csail, intel and freiburg-079 logs, µs per scan, today's code
beside OLD's measured in the same run: OLD's package is exported once (git archive) to a cache
folder and imported in a subprocess with that folder first on sys.path; each version is timed in its own
subprocess, alternately, each log in blocks of 64 scans, best of several passes per block (the least
disturbed by other processes). Target: at most 0.65x OLD's time, aim 0.35x. Today's code is timed on
one thread (like for like: OLD used one) and on all cores (its default); with the leg detector too.

On several cores: features (the shipped leg detector on, no landmarks) of freiburg-079 (or of the hall log tiled
when ../shared/data is absent) on 1 and 2 threads, interleaved, best of repeats. Target: >= 1.7x on 2 cores.
Other processes share the cores: the load average is printed beside the figures.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import print_lines

ROOT = Path(__file__).resolve().parent.parent
CARMEN = ROOT.parent / "shared" / "data" / "carmen"
LOGS = ("csail", "intel", "freiburg-079")
OLD = "cd981b7"
TARGET, AIM = 0.65, 0.35
SPEEDUP_TARGET = 1.7
ROUNDS = 2  # alternating subprocess rounds per version
PASSES = 3  # passes over a log's blocks in one subprocess
CHUNK = 64  # scans per timed extract_run call

# One version's µs/scan per log: argv root, npz paths (comma separated), passes, threads (0: the version has
# no such argument), legs ("1": the shipped leg detector, "0": the paper's rule).
TIMING_CODE = r"""
import json, sys, time
root, paths, passes, threads, legs = sys.argv[1], sys.argv[2].split(","), int(sys.argv[3]), int(sys.argv[4]), \
    sys.argv[5]
sys.path.insert(0, root)
import numpy as np
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.perception import features as F
from datmo_cli.perception.params import FeatureParams
assert F.__file__.startswith(root), F.__file__
kw = {}
if "leg_model" in FeatureParams.__dataclass_fields__:
    kw["params"] = FeatureParams(leg_model="default" if legs == "1" else "paper")
if threads:
    kw["threads"] = threads
out = {}
for path in paths:
    z = np.load(path)
    g = z["geom"]
    geom = ScanGeometry(float(g[0]), float(g[1]), int(g[2]), float(g[3]), float(g[4]), float(g[5]), float(g[6]),
                        "laser")
    run = ScanRun(z["stamps"], z["ranges"], geom)
    chunks = [run.slice(a, min(a + CHUNK, len(run))) for a in range(0, len(run), CHUNK)]
    F.extract_run(chunks[0], landmarks=False, **kw)   # warm-up: load or compile the kernels
    wall = [float("inf")] * len(chunks)
    cpu = [float("inf")] * len(chunks)
    for _ in range(passes):
        for i, c in enumerate(chunks):
            t0, c0 = time.perf_counter(), time.process_time()
            F.extract_run(c, landmarks=False, **kw)
            wall[i] = min(wall[i], time.perf_counter() - t0)
            cpu[i] = min(cpu[i], time.process_time() - c0)
    out[str(z["name"])] = [1e6 * sum(wall) / len(run), 1e6 * sum(cpu) / len(run)]
print(json.dumps(out))
""".replace("CHUNK", str(CHUNK))


def cache_dir(commit: str = OLD) -> Path:
    return Path(tempfile.gettempdir()) / f"datmo-bench-{commit}"


def old_tree(commit: str = OLD) -> tuple[Path | None, str]:
    """The datmo_cli of `commit` exported (once) to its cache folder: (its root, "") or (None, why not)."""
    root = cache_dir(commit) / "tree"
    if (root / "datmo_cli" / "perception" / "features.py").is_file():
        return root, ""
    try:
        tar = subprocess.run(
            ["git", "-C", str(ROOT), "archive", "--format=tar", commit, "datmo_cli"], capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        return None, f"no git export of {commit} ({exc.__class__.__name__}: git or the commit is missing)"
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=root.parent))
    with tarfile.open(fileobj=io.BytesIO(tar)) as t:
        t.extractall(tmp, filter="data")
    try:
        os.replace(tmp, root)
    except OSError:  # exported at once by another run
        shutil.rmtree(tmp, ignore_errors=True)
    return root, ""


def log_arrays() -> tuple[list[Path], str]:
    """The three CARMEN logs imported (once) to .npz files in the cache folder: (paths, "") or ([], why not)."""
    missing = [n for n in LOGS if not (CARMEN / f"{n}-corrected.log.gz").is_file()]
    if missing:
        return [], f"{CARMEN} lacks {', '.join(missing)} (../shared/data exists only beside CI's clone)"
    from datmo_cli.logs.importers import import_log

    out = []
    for name in LOGS:
        src = CARMEN / f"{name}-corrected.log.gz"
        path = cache_dir() / f"{name}-{src.stat().st_size}.npz"
        if not path.is_file():
            run = import_log(src).run
            g = run.geometry
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(
                tmp,
                ranges=run.ranges,
                stamps=run.stamps,
                name=name,
                geom=np.array(
                    [g.angle_min, g.angle_increment, g.n_beams, g.range_min, g.range_max, g.time_increment, g.scan_time]
                ),
            )
            os.replace(tmp, path)
        out.append(path)
    return out, ""


def time_version(root: Path, paths: list[Path], threads: int, legs: bool) -> dict[str, list[float]]:
    """[wall, CPU] µs/scan per log of the code under `root`, in a fresh subprocess."""
    res = subprocess.run(
        [
            sys.executable,
            "-c",
            TIMING_CODE,
            str(root),
            ",".join(map(str, paths)),
            str(PASSES),
            str(threads),
            "1" if legs else "0",
        ],
        capture_output=True,
        text=True,
        cwd=tempfile.gettempdir(),
    )
    if res.returncode:
        raise RuntimeError(f"timing {root} failed: {res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def against_old() -> list[str]:
    """The lines against OLD: µs/scan of OLD and of today's code per log, and the ratios."""
    paths, why = log_arrays()
    if not paths:
        return [f"skipped: {why}"]
    old, why = old_tree()
    if old is None:
        return [f"skipped: {why}"]
    from datmo_cli.perception.threads import available

    cores = available()
    versions = {"old": (old, 0, False), "new1": (ROOT, 1, False), "newN": (ROOT, cores, False)}
    wall: dict[str, dict[str, float]] = {k: {} for k in versions}
    cpu: dict[str, dict[str, float]] = {k: {} for k in versions}
    for _ in range(ROUNDS):
        for key, (root, threads, legs) in versions.items():
            for name, (w, c) in time_version(root, paths, threads, legs).items():
                wall[key][name] = min(wall[key].get(name, float("inf")), w)
                cpu[key][name] = min(cpu[key].get(name, float("inf")), c)
    legs = {name: w for name, (w, _) in time_version(ROOT, paths, 1, True).items()}
    lines = [
        f"µs/scan, segmentation + lines, circles, blobs (paper's leg rule); best of {ROUNDS} alternating "
        f"rounds x {PASSES} passes per {CHUNK}-scan block; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} CPUs. CPU time: the like-for-like figure when other processes share the cores"
    ]
    worst_cpu = worst_wall = worst_n = 0.0
    for name in LOGS:
        o, n1, nN = (wall[k][name] for k in ("old", "new1", "newN"))
        oc, n1c = cpu["old"][name], cpu["new1"][name]
        worst_cpu, worst_wall, worst_n = max(worst_cpu, n1c / oc), max(worst_wall, n1 / o), max(worst_n, nN / o)
        lines.append(
            f"{name:>13}: {OLD} {o:6.1f} (CPU {oc:6.1f})   today, 1 thread {n1:6.1f} (CPU {n1c:6.1f}): "
            f"{n1 / o:.2f}x (CPU {n1c / oc:.2f}x)   {cores} threads {nN:6.1f}: {nN / o:.2f}x   "
            f"+ leg detector, 1 thread {legs[name]:6.1f}"
        )

    def verdict(r: float) -> str:
        return (
            f"{r:.2f}x: target <= {TARGET}x {'met' if r <= TARGET else 'NOT met'}, aim {AIM}x "
            f"{'met' if r <= AIM else 'not met'}"
        )

    lines.append(f"worst log, 1 thread, CPU time (like for like): {verdict(worst_cpu)}")
    lines.append(f"worst log, 1 thread, wall time: {verdict(worst_wall)}")
    lines.append(f"worst log, {cores} threads (the default), wall time: {verdict(worst_n)}")
    return lines


def thread_speedup() -> list[str]:
    """The lines on several cores: features (leg detector on, no landmarks) on 1 and 2 threads."""
    from datmo_cli.logs import mcapio
    from datmo_cli.logs.scan import ScanRun
    from datmo_cli.perception.features import extract_run
    from datmo_cli.perception.threads import available

    if available() < 2:
        return [f"skipped: numba runs {available()} thread here (NUMBA_NUM_THREADS / CPUs)"]
    paths, _ = log_arrays()
    if paths:
        z = np.load(paths[-1])
        from datmo_cli.logs.scan import ScanGeometry

        g = z["geom"]
        run = ScanRun(
            z["stamps"],
            z["ranges"],
            ScanGeometry(
                float(g[0]), float(g[1]), int(g[2]), float(g[3]), float(g[4]), float(g[5]), float(g[6]), "laser"
            ),
        )
        label = f"freiburg-079 ({len(run):,} scans x {run.geometry.n_beams} beams)"
    else:
        from benchmarks.bench_perception import HALL, tiled

        run = tiled(mcapio.read_run(HALL), 5_000)
        label = f"hall tiled ({len(run):,} scans)"
    extract_run(run.slice(0, 64), landmarks=False, threads=1)
    extract_run(run.slice(0, 64), landmarks=False, threads=2)
    best = {1: float("inf"), 2: float("inf")}
    for _ in range(5):
        for n in (1, 2):
            t0 = time.perf_counter()
            extract_run(run, landmarks=False, threads=n)
            best[n] = min(best[n], time.perf_counter() - t0)
    s = best[1] / best[2]
    N = len(run)
    return [
        f"features of {label}, shipped leg detector on, no landmarks; best of 5, interleaved; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (other processes share them)",
        f"1 thread: {N / best[1]:,.0f} scans/s ({1e6 * best[1] / N:.1f} µs/scan); 2 threads: "
        f"{N / best[2]:,.0f} scans/s ({1e6 * best[2] / N:.1f} µs/scan); speed-up {s:.2f}x "
        f"(target >= {SPEEDUP_TARGET}x: {'met' if s >= SPEEDUP_TARGET else 'NOT met'})",
    ]


def main() -> None:
    print_lines(f"Perception against {OLD}", against_old())
    print_lines("Perception on 1 and 2 threads", thread_speedup())


if __name__ == "__main__":
    main()
