"""Scale (make bench): `datmo run` and `datmo features` on long raw logs, in bounded memory.

The 361-beam hall log's scans (/scan only) tiled to 20,000 and 80,000 scans. Printed beside the plain MCAP read speed of
the same file: peak RSS of a whole `datmo run` process on each (targets: within 10 % of each other, both under 400 MB);
`datmo run` and `datmo features` speed on one core with a warm cache (targets: run >= RUN_TARGET scans/s and >= RUN_GAIN
x the BASELINE commit's code measured in the same run, features >= 10,000 scans/s); and output bytes per scan with
--markers and by default (no markers, no covariance; targets: at most 2.5x the input with markers, 1.5x without),
and the same ratios on CARMEN intel (imported from ../shared/data/carmen/intel-corrected.log.gz when present;
target at most 3x without markers). The hall is tiled every 300 scans, a repetition that MCAP chunks spanning
several blocks profit from and real logs do not have: intel is the honest measure of the output's size.
With the report, the process also holds one summary row per track of the run (the report's track table),
so its memory grows with the number of tracks; --no-report shows the pipeline alone. Logs are made once and
kept in the system's temporary folder.
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
from datmo_cli.log import mcapio

ROOT = Path(__file__).resolve().parent.parent
CACHE = Path(tempfile.gettempdir()) / "datmo-bench"
SIZES = (20_000, 80_000)
RSS_TARGET_MB, RSS_SPREAD = 400.0, 0.10
INTEL = ROOT.parent / "shared" / "data" / "carmen" / "intel-corrected.log.gz"
INTEL_TARGETS = {"default (lean)": 3.0, "--markers": 2.5}
RUN_TARGET, RUN_GAIN, FEATURES_TARGET = 6_000, 2.4, 10_000
BASELINE = "513f579"  # the code the second speed round started from: `datmo run`'s gain, measured in the same run

# peak RSS of a child process: the largest resident set of any child waited for, so one child per wrapper
RSS_WRAPPER = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
if done.returncode:
    sys.exit(done.stderr[-2000:])
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
"""


def long_log(n: int) -> Path:
    """The hall's /scan tiled to n scans, written once into CACHE."""
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


def baseline_run_seconds(src: Path, out: Path) -> float | None:
    """Wall time of BASELINE's whole-run `process_file` on `src` (after a warm-up that compiles or loads its
    kernels), in a fresh process with its tree first on the path; None when it cannot run here."""
    tree = baseline_tree()
    if tree is None:
        return None
    code = (
        "import sys, time\nfrom datmo_cli.pipeline import process_file, warm_up\nwarm_up()\n"
        "t0 = time.perf_counter()\nprocess_file(sys.argv[1], sys.argv[2], force=True)\n"
        "print(time.perf_counter() - t0)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run(
        [sys.executable, "-c", code, str(src), str(out)], capture_output=True, text=True, env=env, cwd=tree
    )
    return float(done.stdout.strip().splitlines()[-1]) if done.returncode == 0 else None


def intel_sizes(tmp: Path) -> list[str]:
    """The output ratios of datmo run on CARMEN intel, lean and with --markers, against the targets."""
    from datmo_cli.pipeline import process_file

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
    from datmo_cli.perception.threads import set_default
    from datmo_cli.pipeline import process_file, warm_up
    from datmo_cli.stage_files import features_file

    logs = {n: long_log(n) for n in SIZES}
    small = logs[SIZES[0]]
    n = SIZES[0]
    warm_up()
    set_default(1)  # the one-thread figures (`--threads 1`): bench_threads gives two against one
    lines = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t_read = best_of(lambda: mcap_iterate(small), repeat=3)
        t_read_datmo = best_of(lambda: sum(1 for _ in mcapio.iter_messages(small, [mcapio.TOPIC_SCAN])), repeat=3)
        t_run = best_of(lambda: process_file(small, tmp / "run.mcap", force=True, markers=True), repeat=2)
        t_lean = best_of(lambda: process_file(small, tmp / "lean.mcap", force=True), repeat=1)
        t_feat = best_of(lambda: features_file(small, tmp / "features.mcap", force=True), repeat=2)
        rows = [
            Row("plain MCAP read (mcap's reader, /scan)", n, t_read, "the floor: reading the input"),
            Row("datmo's streaming reader (iter_messages, /scan)", n, t_read_datmo, ""),
            Row(
                "datmo run --markers: segment, features, track, markers, write",
                n,
                t_run,
                f"target >= {RUN_TARGET:,} scans/s",
            ),
            Row("datmo run (lean: no markers, no covariance)", n, t_lean, ""),
            Row(
                "datmo features: segment, features, landmarks, write",
                n,
                t_feat,
                f"target >= {FEATURES_TARGET:,} scans/s",
            ),
        ]
        old = baseline_run_seconds(small, tmp / "old.mcap")
        if old is not None:
            rows.append(Row(f"datmo run at {BASELINE} (the code before this speed round)", n, old, "same run"))
        print_table(f"datmo run and features on the hall tiled to {n:,} scans (361 beams), one core, warm cache", rows)
        lines.append(f"datmo run --markers: {n / t_run:,.0f} scans/s")
        if old is not None:
            gain = old / t_lean
            lines.append(
                f"datmo run (lean, the default): {n / t_lean:,.0f} scans/s, {gain:.2f}x {BASELINE}'s "
                f"{n / old:,.0f} scans/s (its default; targets >= {RUN_TARGET:,}/s, >= {RUN_GAIN:g}x): "
                f"{'met' if n / t_lean >= RUN_TARGET and gain >= RUN_GAIN else 'NOT met'}"
            )
        else:
            lines.append(
                f"datmo run (lean, the default): {n / t_lean:,.0f} scans/s (target >= {RUN_TARGET:,}): "
                f"{'met' if n / t_lean >= RUN_TARGET else 'NOT met'}"
            )
        lines.append(
            f"datmo features: {n / t_feat:,.0f} scans/s (target >= {FEATURES_TARGET:,}): "
            f"{'met' if n / t_feat >= FEATURES_TARGET else 'NOT met'}"
        )
        size_in = small.stat().st_size
        for name, path, target in (("--markers", tmp / "run.mcap", 2.5), ("default (lean)", tmp / "lean.mcap", 1.5)):
            size = path.stat().st_size
            verdict = "met" if size <= target * size_in else "NOT met"
            lines.append(
                f"output {name}: {size / n:,.0f} bytes/scan, {size / size_in:.2f}x the input's "
                f"{size_in / n:,.0f} (target <= {target:g}x): {verdict}"
            )
        lines += intel_sizes(tmp)
        rss: dict[str, dict[int, float]] = {}
        for label, extra in (("datmo run", ("--format", "json")), ("datmo run --no-report", ("--no-report",))):
            got = rss[label] = {}
            for k, path in logs.items():
                got[k] = peak_rss_mb(datmo("run", str(path), "-o", str(tmp / f"rss{k}"), "--force", "-j", "1", *extra))
                lines.append(f"{label} on {k:,} scans: peak RSS {got[k]:,.0f} MB (target < {RSS_TARGET_MB:,.0f} MB)")
            a, b = got[SIZES[0]], got[SIZES[1]]
            spread = abs(b - a) / a
            ok = spread <= RSS_SPREAD and max(a, b) < RSS_TARGET_MB
            lines.append(
                f"{label}: peak RSS {SIZES[1]:,} vs {SIZES[0]:,} scans {100 * spread:+.1f} % (target within "
                f"{100 * RSS_SPREAD:.0f} %, both under {RSS_TARGET_MB:,.0f} MB): {'met' if ok else 'NOT met'}"
            )
    print_lines("Scale: speed, output size and memory against the issue's targets", lines)
    print(
        json.dumps(
            {
                "rss_mb": rss,
                "run_scans_per_s": n / t_run,
                "features_scans_per_s": n / t_feat,
                "read_scans_per_s": n / t_read,
                "time": time.strftime("%Y-%m-%d %H:%M"),
            }
        )
    )


if __name__ == "__main__":
    main()
