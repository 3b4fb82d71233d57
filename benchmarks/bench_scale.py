"""Scale (make bench): `datmo run` and `datmo features` on long raw logs, in bounded memory.

Two logs of the 361-beam hall, /scan only: the sample hall's 300 scans tiled to 20,000 (a repetition that MCAP
chunks and caches profit from and real logs do not have), and the hall simulated at 37.5 Hz for 20,025 scans
(benchmarks/hall_log: non-repeating, the honest one). On each, `datmo features --threads 1` and `datmo run
--threads 1` (the default, lean) are timed in fresh processes with a warm cache, this code's and the BASELINE
commit's (a worktree of it, made once), interleaved, best of REPEAT: the gains against RUN_GAIN and
FEATURES_GAIN are judged on the simulated hall (wall time; the processes' CPU time beside it, the honest
figure on a busy machine). Then, on the tiled hall, the stages beside the plain MCAP read speed of the same
file, and output bytes per scan with --markers and by default (targets: at most 2.5x the input with markers,
1.5x without), and the same ratios on CARMEN intel (imported from ../shared/data/carmen/intel-corrected.log.gz
when present; target at most 3x without markers): intel is the honest measure of the output's size. Last, the
peak RSS of a whole `datmo run` process on the simulated hall of 20,000 and 80,000 scans (targets: within 10 % of
each other, both under 400 MB). With the report, the process also holds one summary row per track of the run,
so its memory grows with the number of tracks. Logs are made once and kept in the system's temporary folder.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.bench_perception import HALL, mcap_iterate, tiled
from benchmarks.common import Row, best_of, print_lines, print_table
from benchmarks.hall_log import HALL_SCANS, simulated_hall
from datmo_cli.logs import mcapio

ROOT = Path(__file__).resolve().parent.parent
CACHE = Path(tempfile.gettempdir()) / "datmo-bench"
SIZES = (20_000, 80_000)  # scans of the simulated hall whose peak RSS is compared
RSS_TARGET_MB, RSS_SPREAD = 400.0, 0.10
INTEL = ROOT.parent / "shared" / "data" / "carmen" / "intel-corrected.log.gz"
INTEL_TARGETS = {"default (lean)": 3.0, "--markers": 2.5}
RUN_TARGET, FEATURES_TARGET = 6_000, 10_000  # scans/s on the tiled hall
RUN_GAIN, FEATURES_GAIN = 2.0, 2.2  # x BASELINE's speed on the simulated hall (issue 34), one thread
BASELINE = "a932713"  # the code the third speed round started from, measured in the same run
REPEAT = 2  # timed processes of each code and command, interleaved

# one timed pass of `datmo features` or `datmo run` with one perception thread, in a fresh process whose tree
# is first on the path: warm_up first (compiles or loads the kernels), then wall and CPU seconds of the pass
TIMED = """
import sys, time
from datmo_cli.perception.threads import set_default
from datmo_cli.passes.pipeline import process_file
from datmo_cli.passes.stage_files import features_file
try:
    from datmo_cli.passes.warm import warm_up
except ImportError:  # a tree from before datmo_cli.passes.warm (BASELINE)
    from datmo_cli.passes.pipeline import warm_up
warm_up()
set_default(1)
command, src, out = sys.argv[1:4]
t0, c0 = time.perf_counter(), time.process_time()
(features_file if command == "features" else process_file)(src, out, force=True)
print(time.perf_counter() - t0, time.process_time() - c0)
"""

# peak RSS of a child process: the largest resident set of any child waited for, so one child per wrapper
RSS_WRAPPER = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
if done.returncode:
    sys.exit(done.stderr[-2000:])
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
"""


def long_log(n: int) -> Path:
    """The sample hall's /scan tiled to n scans, written once into CACHE."""
    path = CACHE / f"hall-{n}.mcap"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        run = tiled(mcapio.read_run(HALL), n)
        with mcapio.LogWriter(path, force=True) as w:
            w.write_scans(run)
    return path


def datmo(*args: str) -> list[str]:
    return [sys.executable, "-c", "from datmo_cli.cli import main; main()", *args]


def peak_rss_mb(command: list[str], env: dict | None = None) -> float:
    """Peak resident memory of `command`'s process, MB."""
    done = subprocess.run([sys.executable, "-c", RSS_WRAPPER, *command], capture_output=True, text=True, env=env)
    if done.returncode:
        raise RuntimeError(done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "failed")
    return float(done.stdout.strip())


def baseline_tree() -> Path | None:
    """A git worktree of BASELINE beside the bench logs (made once), or None without git."""
    tree = CACHE / f"datmo-{BASELINE}"
    if (tree / "datmo_cli").exists():
        return tree
    done = subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(tree), BASELINE],
        capture_output=True,
        text=True,
    )
    return tree if done.returncode == 0 else None


def timed_pass(tree: Path, command: str, src: Path, out: Path) -> tuple[float, float] | None:
    """(wall s, CPU s) of one `datmo <command> --threads 1` pass over `src` by the code of `tree` (TIMED), or None
    when it cannot run here."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run(
        [sys.executable, "-c", TIMED, command, str(src), str(out)], capture_output=True, text=True, env=env, cwd=tree
    )
    if done.returncode:
        return None
    wall, cpu = done.stdout.strip().splitlines()[-1].split()
    return float(wall), float(cpu)


def gains(logs: dict[str, Path], tmp: Path) -> tuple[list[Row], list[str], dict]:
    """This code's and BASELINE's `datmo features` and `datmo run` (one thread) on each log, best of REPEAT
    interleaved: the rows, the lines against FEATURES_GAIN and RUN_GAIN (judged on the simulated hall) and the
    figures {log: {command: {code: (wall, cpu)}}}."""
    old = baseline_tree()
    trees = {"this code": ROOT, **({BASELINE: old} if old is not None else {})}
    best: dict = {}
    for _ in range(REPEAT):
        for log, src in logs.items():
            for command in ("features", "run"):
                for code, tree in trees.items():
                    got = timed_pass(tree, command, src, tmp / f"{command}-{code}.mcap")
                    if got is None:
                        continue
                    have = best.setdefault(log, {}).setdefault(command, {}).get(code, (float("inf"),) * 2)
                    best[log][command][code] = (min(have[0], got[0]), min(have[1], got[1]))
    rows, lines = [], []
    targets = {"features": FEATURES_GAIN, "run": RUN_GAIN}
    for log, src in logs.items():
        n = mcapio.summary(src).topics()[mcapio.TOPIC_SCAN].count
        for command, codes in best.get(log, {}).items():
            for code, (wall, _) in codes.items():
                rows.append(Row(f"datmo {command} --threads 1, {code}, {log}", n, wall, "same run"))
            if BASELINE not in codes or "this code" not in codes:
                lines.append(f"{log}: datmo {command}: {BASELINE}'s code did not run here; no gain measured")
                continue
            (w_new, c_new), (w_old, c_old) = codes["this code"], codes[BASELINE]
            gain, target = w_old / w_new, targets[command]
            judged = log.startswith("simulated")
            verdict = (" (target >= " + f"{target:g}x): " + ("met" if gain >= target else "NOT met")) if judged else ""
            lines.append(
                f"{log}: datmo {command} --threads 1: {n / w_new:,.0f} scans/s, {gain:.2f}x {BASELINE}'s "
                f"{n / w_old:,.0f} (CPU time {c_old / c_new:.2f}x){verdict}"
            )
    return rows, lines, best


def intel_sizes(tmp: Path) -> list[str]:
    """The output ratios of datmo run on CARMEN intel, lean and with --markers, against the targets."""
    from datmo_cli.passes.pipeline import process_file

    if not INTEL.exists():
        return [f"intel: {INTEL} is absent; its output sizes are not measured"]
    src = tmp / "intel.mcap"
    subprocess.run(datmo("import", str(INTEL), "-o", str(src), "--force"), check=True, capture_output=True)
    size_in = src.stat().st_size
    lines = []
    for name, markers in (("default (lean)", False), ("--markers", True)):
        out = tmp / f"intel-{markers}.mcap"
        process_file(src, out, force=True, markers=markers)
        ratio = out.stat().st_size / size_in
        target = INTEL_TARGETS[name]
        lines.append(
            f"intel output {name}: {out.stat().st_size:,} bytes, {ratio:.2f}x the input's {size_in:,} (target <= "
            f"{target:g}x): {'met' if ratio <= target else 'NOT met'}"
        )
    return lines


def main() -> None:
    from datmo_cli.passes.pipeline import process_file
    from datmo_cli.passes.stage_files import features_file
    from datmo_cli.passes.warm import warm_up
    from datmo_cli.perception.threads import set_default

    n = 20_000
    small = long_log(n)
    simulated = {k: simulated_hall(k) for k in (HALL_SCANS, *SIZES)}
    warm_up()
    set_default(1)  # the one-thread figures (`--threads 1`): bench_threads gives two against one
    lines = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        logs = {f"simulated hall ({HALL_SCANS:,} scans)": simulated[HALL_SCANS], f"tiled hall ({n:,} scans)": small}
        rows, gain_lines, best = gains(logs, tmp)
        print_table(f"datmo features and run, one thread, this code and {BASELINE}'s (fresh processes)", rows)
        lines += gain_lines
        t_read = best_of(lambda: mcap_iterate(small), repeat=3)
        t_read_datmo = best_of(lambda: sum(1 for _ in mcapio.iter_messages(small, [mcapio.TOPIC_SCAN])), repeat=3)
        t_run = best_of(lambda: process_file(small, tmp / "run.mcap", force=True, markers=True), repeat=2)
        t_lean = best_of(lambda: process_file(small, tmp / "lean.mcap", force=True), repeat=1)
        t_feat = best_of(lambda: features_file(small, tmp / "features.mcap", force=True), repeat=2)
        rows = [
            Row("plain MCAP read (mcap's reader, /scan)", n, t_read, "the floor: reading the input"),
            Row("datmo's streaming reader (iter_messages, /scan)", n, t_read_datmo, ""),
            Row("datmo run --markers: segment, features, track, markers, write", n, t_run, ""),
            Row("datmo run (lean: no markers, no covariance)", n, t_lean, f"target >= {RUN_TARGET:,} scans/s"),
            Row(
                "datmo features: segment, features, landmarks, write",
                n,
                t_feat,
                f"target >= {FEATURES_TARGET:,} scans/s",
            ),
        ]
        print_table(f"datmo run and features on the hall tiled to {n:,} scans (361 beams), one core, warm cache", rows)
        lines.append(f"tiled: datmo run --markers: {n / t_run:,.0f} scans/s")
        for name, t, target in (("datmo run (lean)", t_lean, RUN_TARGET), ("datmo features", t_feat, FEATURES_TARGET)):
            lines.append(
                f"tiled: {name}: {n / t:,.0f} scans/s (target >= {target:,}): {'met' if n / t >= target else 'NOT met'}"
            )
        size_in = small.stat().st_size
        for name, path, target in (("--markers", tmp / "run.mcap", 2.5), ("default (lean)", tmp / "lean.mcap", 1.5)):
            size = path.stat().st_size
            verdict = "met" if size <= target * size_in else "NOT met"
            lines.append(
                f"tiled: output {name}: {size / n:,.0f} bytes/scan, {size / size_in:.2f}x the input's "
                f"{size_in / n:,.0f} (target <= {target:g}x): {verdict}"
            )
        lines += intel_sizes(tmp)
        rss: dict[int, float] = {}
        for k in SIZES:
            cmd = datmo("run", str(simulated[k]), "-o", str(tmp / f"rss{k}"), "--force", "-j", "1", "--format", "json")
            rss[k] = peak_rss_mb(cmd)
            lines.append(f"datmo run on the simulated hall's {k:,} scans: peak RSS {rss[k]:,.0f} MB")
        a, b = rss[SIZES[0]], rss[SIZES[1]]
        spread = (b - a) / a
        ok = abs(spread) <= RSS_SPREAD and max(a, b) < RSS_TARGET_MB
        lines.append(
            f"datmo run: peak RSS {SIZES[1]:,} vs {SIZES[0]:,} simulated scans {100 * spread:+.1f} % (target within "
            f"{100 * RSS_SPREAD:.0f} %, both under {RSS_TARGET_MB:,.0f} MB): {'met' if ok else 'NOT met'}"
        )
    print_lines("Scale: speed, output size and memory against the issue's targets", lines)
    print(
        json.dumps(
            {
                "rss_mb": rss,
                "gains": best,
                "tiled_run_scans_per_s": n / t_lean,
                "tiled_features_scans_per_s": n / t_feat,
                "read_scans_per_s": n / t_read,
                "time": time.strftime("%Y-%m-%d %H:%M"),
            }
        )
    )


if __name__ == "__main__":
    main()
