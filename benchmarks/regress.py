"""CI regression: `datmo run` and `datmo evaluate` on every sample log, compared with a committed baseline.

    python -m benchmarks.regress            # make regress: fail (exit 1) when a figure got worse
    python -m benchmarks.regress --update   # make regress-update: rewrite the baseline from this run

The baseline, tests/regress_baseline.json, holds the figures per log and the tolerances. A figure fails
when it is worse than its baseline by more than its tolerance:
- ratios where higher is better (MOTA, IDF1, precision, recall): a fall of more than `ratio` (absolute);
- MOTP (mean match distance, m): a rise of more than `motp_m` metres;
- counts where lower is better (false positives, misses, ID switches): a rise of more than
  max(`count_abs`, `count_rel` x baseline).
Improvements never fail; they are printed so the baseline can be raised with `make regress-update`.
Logs without ground truth (the real-data excerpt) are run and reported, and recorded for information.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "tests" / "regress_baseline.json"
SAMPLE_LOGS = ROOT / "sample_logs"
FIGURES = ("mota", "motp", "idf1", "precision", "recall", "num_false_positives", "num_misses", "num_switches")
RATIOS = ("mota", "idf1", "precision", "recall")
COUNTS = ("num_false_positives", "num_misses", "num_switches")
DEFAULT_TOLERANCE = {"ratio": 0.02, "motp_m": 0.02, "count_abs": 3, "count_rel": 0.10}
INFO = ("tracks", "dynamic", "person")  # report figures recorded for logs without ground truth


def datmo_command() -> list[str]:
    """The datmo CLI of this interpreter's environment."""
    script = Path(sys.executable).with_name("datmo")
    return [str(script)] if script.exists() else [sys.executable, "-c", "from datmo_cli.cli import main; main()"]


def sample_logs() -> list[Path]:
    return sorted(SAMPLE_LOGS.glob("*.mcap"))


def measure(logs: list[Path], out_dir: Path, jobs: int | None = None) -> tuple[dict[str, dict], list[str]]:
    """Run datmo run on `logs` into `out_dir`, then datmo evaluate (or report, without ground truth) on
    each output. Returns ({log stem: figures}, [problems])."""
    datmo = datmo_command()
    run = [*datmo, "run", *map(str, logs), "-o", str(out_dir), "--force", "--format", "json"]
    if jobs:
        run += ["--jobs", str(jobs)]
    done = subprocess.run(run, capture_output=True, text=True)
    problems = [line for line in done.stderr.splitlines() if line.startswith("datmo: error")]
    figures: dict[str, dict] = {}
    for log in logs:
        out = out_dir / log.name
        if not out.exists():
            problems.append(f"{log.name}: datmo run wrote no output")
            continue
        ev = subprocess.run([*datmo, "evaluate", str(out), "--format", "json"], capture_output=True, text=True)
        if ev.returncode == 0:
            scores = json.loads(ev.stdout)["scores"]
            fig = {k: scores["all"][k] for k in FIGURES}
            fig["per_class"] = {
                name: {k: s[k] for k in ("mota", "idf1")} for name, s in scores.items() if name != "all"
            }
            figures[log.stem] = fig
        elif "no messages on /datmo/ground_truth" in ev.stderr:
            rep = subprocess.run([*datmo, "report", str(out), "--format", "json"], capture_output=True, text=True)
            if rep.returncode:
                problems.append(f"{log.name}: datmo report failed: {rep.stderr.strip()}")
                continue
            row = json.loads(rep.stdout)["files"][0]
            figures[log.stem] = {
                "ground_truth": False,
                "tracks": row["tracks"],
                "dynamic": row["dynamic"],
                "person": row["person"],
            }
        else:
            problems.append(f"{log.name}: datmo evaluate failed: {ev.stderr.strip()}")
    return figures, problems


def compare(baseline: dict[str, dict], current: dict[str, dict], tolerance: dict | None = None) -> tuple[list, list]:
    """(failures, notes): figures worse than the baseline beyond tolerance, and improvements or new logs."""
    tol = {**DEFAULT_TOLERANCE, **(tolerance or {})}
    failures, notes = [], []
    for name, base in sorted(baseline.items()):
        cur = current.get(name)
        if cur is None:
            failures.append(f"{name}: no figures (the run or the evaluation failed)")
            continue
        if base.get("ground_truth") is False:
            continue
        for key in FIGURES:
            b, c = base.get(key), cur.get(key)
            if b is None:
                continue
            if c is None:
                failures.append(f"{name}: {key} is undefined (baseline {b:.3f})")
                continue
            if key in RATIOS:
                worse, allowed = b - c, tol["ratio"]
            elif key == "motp":
                worse, allowed = c - b, tol["motp_m"]
            else:
                worse, allowed = c - b, max(tol["count_abs"], tol["count_rel"] * b)
            if worse > allowed + 1e-12:
                failures.append(
                    f"{name}: {key} {_fmt(c)} is worse than the baseline {_fmt(b)} "
                    f"by {_fmt(worse)} (tolerance {_fmt(allowed)})"
                )
            elif worse < -1e-9:
                notes.append(f"{name}: {key} improved from {_fmt(b)} to {_fmt(c)}")
    for name in sorted(set(current) - set(baseline)):
        notes.append(f"{name}: not in the baseline (add it with make regress-update)")
    return failures, notes


def _fmt(v: float) -> str:
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--update", action="store_true", help="rewrite the baseline from this run")
    parser.add_argument("--baseline", type=Path, default=BASELINE)
    parser.add_argument("--jobs", type=int, default=None, help="parallel datmo run jobs [default: all cores]")
    parser.add_argument("--out", type=Path, default=None, help="keep the processed logs here")
    args = parser.parse_args(argv)
    if not args.update and not args.baseline.exists():
        print(f"regress: {args.baseline} does not exist; make it with make regress-update", file=sys.stderr)
        return 1
    logs = sample_logs()
    if not logs:
        print(f"regress: no sample logs in {SAMPLE_LOGS}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="datmo-regress-") as tmp:
        out = args.out or Path(tmp)
        os.makedirs(out, exist_ok=True)
        current, problems = measure(logs, out, args.jobs)
    for line in problems:
        print(f"regress: {line}", file=sys.stderr)
    if args.update:
        if problems:
            print("regress: not updating the baseline while runs fail", file=sys.stderr)
            return 1
        old = json.loads(args.baseline.read_text()) if args.baseline.exists() else {}
        data = {"tolerance": old.get("tolerance", DEFAULT_TOLERANCE), "logs": current}
        args.baseline.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
        print(f"regress: wrote {args.baseline} ({len(current)} logs); review and commit it")
        return 0
    base = json.loads(args.baseline.read_text())
    failures, notes = compare(base["logs"], current, base.get("tolerance"))
    for name, fig in sorted(current.items()):
        shown = ", ".join(f"{k} {_fmt(fig[k])}" for k in FIGURES if fig.get(k) is not None) or ", ".join(
            f"{k} {fig[k]}" for k in INFO if k in fig
        )
        print(f"{name}: {shown}")
    for line in notes:
        print(f"note: {line}")
    for line in failures:
        print(f"REGRESSION: {line}")
    ok = not failures and not problems
    print("regress: ok" if ok else f"regress: {len(failures) + len(problems)} problem(s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
