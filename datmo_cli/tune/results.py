"""The outputs of `datmo tune` in DIR: trials.parquet (one row per trial: its parameters, its figures per log at
its last rung, the objective's mean, seconds), best.toml (a config `--config` reads: the best setting, with
the objective's name and value and the evidence in comments), tune.png with --plot (the objective against each
parameter, and the best trial's figures per log), and the rows of the table the command prints.

Figures as `datmo evaluate` gives them (MOTP in metres, rates per second of log); parameters in their units.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

from .objective import SHOWN

if TYPE_CHECKING:
    from .outcome import TuneResult
    from .search import Score

TRIALS, BEST, PLOT = "trials.parquet", "best.toml", "tune.png"


def shown_metrics(result: TuneResult) -> list[str]:
    """The figures kept per log: the objective, the constraints' figures, then objective.SHOWN."""
    names = [result.goal.objective, *(c.name for c in result.goal.constraints), *SHOWN]
    return list(dict.fromkeys(names))


def fmt(v: object) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4f}" if abs(v) < 1000 else f"{v:,.0f}"
    return str(v)


def rows(result: TuneResult) -> dict[str, list]:
    """The columns of trials.parquet (one entry per trial, in trial order)."""
    metrics = shown_metrics(result)
    cols: dict[str, list] = {
        k: [] for k in ("trial", "start", "status", "error", "rung", "log_fraction", result.goal.objective, "seconds")
    }
    for d in result.dims:
        cols[d.key] = []
    for c in result.goal.constraints:
        cols.setdefault(c.name, [])
    for log in result.logs:
        for m in metrics:
            cols[f"{log.name}:{m}"] = []
    for t in result.trials:
        s = result.scores[t.index]
        row = {
            "trial": t.index,
            "start": t.index == 0,
            "status": "refused" if t.config is None else "failed" if s.error else "scored",
            "error": s.error,
            "rung": t.rung,
            "log_fraction": result.fractions[t.rung] if t.rung >= 0 else None,
            result.goal.objective: s.value,
            "seconds": round(s.seconds, 3),
            **t.values,
            **s.constrained,
        }
        for log in result.logs:
            figures = s.per_log.get(log.name, {})
            for m in metrics:
                row[f"{log.name}:{m}"] = figures.get(m)
        for k, column in cols.items():
            column.append(row.get(k))
    return cols


def best_toml(result: TuneResult) -> str:
    """best.toml: the best setting as a config file (the tuned keys, and every key where the start differs from
    the defaults), its objective and evidence in comments."""
    from ..passes.config import DatmoConfig, to_toml

    best, score, goal = result.best, result.best_score, result.goal
    defaults = DatmoConfig().to_dict()
    assert best.config is not None  # the best trial was scored
    tables = best.config.to_dict()
    dims = {d.key: d for d in result.dims}
    kept: dict[str, dict] = {}
    sources: dict[str, dict[str, str]] = {}
    for section, table in tables.items():
        kept[section], sources[section] = {}, {}
        for key, value in table.items():
            full = f"{section}.{key}"
            if full in dims:
                kept[section][key], sources[section][key] = value, f"tuned: {dims[full].describe()}"
            elif value != defaults[section][key]:
                kept[section][key], sources[section][key] = value, "from the start config"
    better = "higher" if goal.higher else "lower"
    lines = [
        f"datmo tune: the best of {len(result.trials)} trials (trial {best.index}) on {len(result.logs)} "
        f"log{'s' if len(result.logs) > 1 else ''}",
        f"objective: {goal.objective} = {score.value!r} (mean over the logs, whole logs; {better} is better)",
        f"start (trial 0): {goal.objective} = {fmt(result.start_score.value)}",
    ]
    for c in goal.constraints:
        met = "met" if c.met(score.constrained.get(c.name)) else "NOT met"
        lines.append(f"constraint {c.describe()}: {fmt(score.constrained.get(c.name))} ({met})")
    for log in result.logs:
        figures = score.per_log.get(log.name, {})
        shown = ", ".join(f"{m} {fmt(figures.get(m))}" for m in shown_metrics(result)[:6])
        lines.append(f"{log.name}: {shown}")
    for fold in result.folds:
        lines.append(
            f"cv: tuned without {fold.held_out}: trial {fold.best}, {goal.objective} {fmt(fold.tuned)} tuned, "
            f"{fmt(fold.held_out_value)} on {fold.held_out} (held out)"
        )
    lines.append(f"use: datmo run LOGS -o OUT --config {BEST}")
    return to_toml(kept, sources, header="\n".join(lines))


def write_outputs(result: TuneResult, *, plot: bool = False) -> list[Path]:
    """trials.parquet, best.toml (and tune.png with `plot`) in the tune's folder, each replaced atomically;
    returns their paths."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..base.outputs import atomic_output

    out = result.out_dir
    buf = io.BytesIO()
    pq.write_table(pa.table(rows(result)), buf)
    with atomic_output(out / TRIALS, force=True, what="trials table") as f:
        f.write(buf.getvalue())
    with atomic_output(out / BEST, force=True, what="best config") as f:
        f.write(best_toml(result).encode("utf-8"))
    paths = [out / TRIALS, out / BEST]
    if plot:
        paths.append(draw(result, out / PLOT))
    return paths


def tables(result: TuneResult, top: int = 10) -> list:
    """The tables the command prints (report.Table): the best trials on the whole logs, best first (at most
    `top`), and with --cv the folds (each held-out log's figure beside the tuned one)."""
    from ..report import Table
    from .search import rank_key

    final = len(result.fractions) - 1
    done = [t for t in result.trials if t.rung == final]
    ranked = sorted(done, key=lambda t: rank_key(t, result.scores[t.index], result.goal))[:top]
    goal = result.goal
    columns = ["trial", *(d.key for d in result.dims), goal.objective, *(c.name for c in goal.constraints)]
    columns += [f"{log.name}" for log in result.logs] + ["s"]
    out = []
    for t in ranked:
        s: Score = result.scores[t.index]
        cells = [f"{t.index}{' (start)' if t.index == 0 else ''}", *(fmt(t.values[d.key]) for d in result.dims)]
        cells += [fmt(s.value), *(fmt(s.constrained.get(c.name)) for c in goal.constraints)]
        cells += [fmt(s.per_log.get(log.name, {}).get(goal.objective)) for log in result.logs]
        out.append([*cells, f"{s.seconds:.1f}"])
    title = (
        f"best trials on the whole logs ({len(done)} of {len(result.trials)} reached them; per-log columns: "
        f"{goal.objective})"
    )
    out_tables = [Table(title, columns, out, set(range(1, len(columns))))]
    if result.folds:
        fold_rows = [[f.held_out, str(f.best), fmt(f.tuned), fmt(f.held_out_value)] for f in result.folds]
        fold_rows.append(
            [
                "mean",
                "",
                fmt(_mean([f.tuned for f in result.folds])),
                fmt(_mean([f.held_out_value for f in result.folds])),
            ]
        )
        cv_columns = ["held out", "best trial", f"{goal.objective} tuned (other logs)", f"{goal.objective} held out"]
        out_tables.append(Table("leave-one-log-out (--cv)", cv_columns, fold_rows, {1, 2, 3}))
    return out_tables


def _mean(values: list[float | None]) -> float | None:
    from .objective import mean

    return mean(list(values))


def draw(result: TuneResult, path: Path) -> Path:
    """tune.png: the objective against each parameter (each trial at its last rung; the whole-log trials
    filled, the best ringed) and the best trial's shown figures per log, drawn as the report's plot is (a
    matplotlib Figure on the Agg canvas, constrained layout, light grids, 150 dpi)."""
    from matplotlib.figure import Figure

    from ..base.outputs import atomic_output

    dims, goal = result.dims, result.goal
    final = len(result.fractions) - 1
    fig = Figure(figsize=(4.0 * (len(dims) + 1), 3.8), layout="constrained")
    axes = fig.subplots(1, len(dims) + 1, squeeze=False)
    for ax, d in zip(axes[0], dims, strict=False):
        for t in result.trials:
            s: Score = result.scores[t.index]
            if s.value is None:
                continue
            x = t.values[d.key]
            x = d.choices.index(x) if d.choices else x
            whole = t.rung == final
            ax.plot(x, s.value, "o", color="tab:blue" if whole else "tab:gray", alpha=1.0 if whole else 0.5, ms=5)
            if t is result.best:
                ax.plot(x, s.value, "o", mfc="none", mec="tab:red", ms=11, mew=2)
        if d.choices:
            ax.set_xticks(range(len(d.choices)), [str(c) for c in d.choices])
        if d.log:
            ax.set_xscale("log")
        ax.set_xlabel(d.key)
        ax.set_ylabel(goal.objective)
        ax.grid(True, lw=0.3, alpha=0.5)
    ax = axes[0][-1]
    _per_log(ax, result)
    fig.suptitle(
        f"datmo tune: {goal.objective} of {len(result.trials)} trials "
        "(blue: on the whole logs, grey: on a prefix only; ringed: the best)"
    )
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=150)
    with atomic_output(path, force=True, what="plot") as f:
        f.write(buf.getvalue())
    return path


def _per_log(ax, result: TuneResult) -> None:
    """Bars of the best trial's ratio figures (HOTA, MOTA, IDF1, ...) per log."""
    import numpy as np

    figures = [m for m in ("hota", "mota", "idf1", "people_mota") if m in shown_metrics(result)]
    logs = [log.name for log in result.logs]
    width = 0.8 / max(len(figures), 1)
    for i, m in enumerate(figures):
        values = [result.best_score.per_log.get(name, {}).get(m) for name in logs]
        ax.bar(np.arange(len(logs)) + i * width, [v if v is not None else 0.0 for v in values], width, label=m)
    ax.set_xticks(np.arange(len(logs)) + 0.4 - width / 2, logs, rotation=20, ha="right")
    ax.set_title(f"trial {result.best.index} per log", fontsize="medium")
    ax.set_ylim(min(0.0, ax.get_ylim()[0]), 1.15)
    ax.legend(fontsize="small", loc="upper right", ncol=len(figures))
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
