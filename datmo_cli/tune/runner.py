"""`datmo tune` as one call (`run_tune`): everything checked before anything is written (the space, the logs'
ground truth, the objective and constraints, the extras the outputs need), then the search on local processes
or a Dask cluster, the leave-one-log-out folds with --cv, and the outputs (results.write_outputs).

DIR/tune.json records what the tune is (logs, space, objective, constraints, trials, seed, start; not --cv,
which adds folds to the same tune); running
the same tune again in DIR continues it (or, finished, re-prints its result at no cost); a different tune in a
DIR that holds one needs --force (its outputs would be replaced).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from ..base.errors import ConfigError, DatmoError
from .objective import Constraint, check_name, higher_is_better, parse_constraint
from .outcome import Fold, TuneResult
from .search import Evaluations, Goal, TuneInterrupted, halving, rungs, settings
from .space import load_space
from .trial import LogInput, log_input

if TYPE_CHECKING:
    from ..batch.executors import Executor

SPEC = "tune.json"


def _check_logs(logs: list[str | Path]) -> list[LogInput]:
    if not logs:
        raise ConfigError("no logs: give at least one log with ground truth")
    out = [log_input(p) for p in logs]
    seen: dict[str, str] = {}
    for log in out:
        if log.name in seen:
            raise ConfigError(f"{log.path}: a second log named {log.name} (the outputs name logs by file name)")
        seen[log.name] = log.path
    return out


def _spec(logs, dims, goal, trials, seed, base) -> dict:
    from ..batch.task import params_hash

    return {
        "logs": [{"path": log.path, "sha256": log.sha256} for log in logs],
        "space": [d.spec() for d in dims],
        "objective": goal.objective,
        "constraints": [c.describe() for c in goal.constraints],
        "trials": trials,
        "seed": seed,
        "start": params_hash(base),
    }


def _check_folder(out_dir: Path, spec: dict, force: bool) -> None:
    """Refuse a DIR holding another tune (without --force): its outputs would be replaced."""
    path = out_dir / SPEC
    from ..batch.manifest import MANIFEST

    if (out_dir / MANIFEST).exists() and not path.is_file():
        raise DatmoError(
            f"{out_dir}: holds a datmo run batch ({MANIFEST} without {SPEC}); give datmo tune a folder of its own"
        )
    if force or not path.is_file():
        return
    try:
        held = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        held = None
    if held != spec:
        raise DatmoError(
            f"{out_dir}: holds another tune ({SPEC} differs: other logs, space, objective, trials, seed or start); "
            "use --force to replace its outputs, or another -o folder"
        )


def run_tune(
    logs: list[str | Path],
    space: str | Path,
    out_dir: str | Path,
    *,
    config=None,
    objective: str = "hota",
    maxima: list[str] | tuple[str, ...] = (),
    minima: list[str] | tuple[str, ...] = (),
    trials: int = 24,
    seed: int = 0,
    cv: bool = False,
    jobs: int | None = None,
    scheduler: str | None = None,
    retries: int = 2,
    force: bool = False,
    plot: bool = False,
    min_prefix_s: float | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> TuneResult:
    """`datmo tune` (docs/tune.md; datmo_cli.api.tune): search the parameters of the TOML file `space` (see
    tune.space) on `logs` (logs with ground truth) from `config` (trial 0: a DatmoConfig, a TOML file, a dict
    of overrides, or None for the defaults), into `out_dir` (trials.parquet, best.toml, manifest.jsonl).
    `objective`: a figure `datmo evaluate` prints, averaged over the logs; `maxima`/`minima`: constraints
    "NAME=VALUE" (tune.objective); `jobs`/`scheduler`/`retries` as for `datmo run`; `progress(done, total,
    what)` follows the evaluations of each rung. Returns a TuneResult (its outputs written): `.best` (the
    trial: `.index`, `.values`, `.config`), `.best_score` (`.value`, `.per_log`), `.start_score`, `.trials`,
    `.folds` (with `cv`)."""
    import os

    from ..base.extras import require
    from ..workflows import as_config

    goal = Goal(
        check_name(objective, "--objective"),
        higher_is_better(objective),
        tuple(parse_constraint(t, True) for t in maxima) + tuple(parse_constraint(t, False) for t in minima),
    )
    if scheduler is not None and jobs is not None:
        raise DatmoError("--jobs is for local runs; with --scheduler the cluster's workers run the trials")
    if trials < 1:
        raise ConfigError(f"--trials {trials}: at least 1")
    dims = load_space(space)
    inputs = _check_logs([os.fsdecode(p) for p in logs])
    if cv and len(inputs) < 2:
        raise ConfigError("--cv leaves one log out at a time: give at least 2 logs")
    require("pyarrow.parquet", for_="DIR/trials.parquet (datmo tune)")
    require("scipy.stats", for_="the Sobol samples of datmo tune")
    from ..evaluate.scoring import require_scoring

    require_scoring("datmo tune (it scores as datmo evaluate)")
    if plot:
        require("matplotlib", for_="--plot")
    base = as_config(config)
    out = Path(out_dir).resolve()
    spec = _spec(inputs, dims, goal, trials, seed, base)
    _check_folder(out, spec, force)
    from ..batch.folder import folder_lock

    with folder_lock(str(out)):
        from ..base.outputs import atomic_output

        with atomic_output(out / SPEC, force=True, what="tune record") as f:
            f.write((json.dumps(spec, indent=1) + "\n").encode("utf-8"))
        executor = _Executor(jobs, scheduler, retries)
        try:
            result = _search(inputs, dims, goal, base, trials, seed, cv, out, executor, force, min_prefix_s, progress)
        except KeyboardInterrupt:  # between two rungs' evaluations (during them: Evaluations says how many)
            raise TuneInterrupted(
                f"interrupted: the evaluations done are in {out / 'manifest.jsonl'}; run the same command again "
                "to continue"
            ) from None
        finally:
            executor.close()
        from .results import write_outputs

        result.outputs = write_outputs(result, plot=plot)
    return result


class _Executor:
    """The executor of the evaluations, started when the first ones are to run (a finished tune run again
    starts no pool and no cluster): a Dask cluster (`scheduler`) or local processes (`jobs`)."""

    def __init__(self, jobs: int | None, scheduler: str | None, retries: int) -> None:
        self.jobs, self.scheduler, self.retries = jobs, scheduler, retries
        self.executor: Executor | None = None

    def run(self, tasks, on_record, on_scans=None) -> None:
        if self.executor is None:
            if self.scheduler is not None:
                from ..batch.cluster import DaskExecutor

                self.executor = DaskExecutor(self.scheduler, retries=self.retries)
            else:
                from ..batch.executors import LocalExecutor

                self.executor = LocalExecutor(self.jobs)
        self.executor.run(tasks, on_record, on_scans)

    def close(self) -> None:
        if self.executor is not None:
            self.executor.close()


def _search(inputs, dims, goal, base, trials, seed, cv, out, executor, force, min_prefix_s, progress) -> TuneResult:
    from .search import MIN_PREFIX_S

    every = settings(base, dims, trials, seed)
    fractions = rungs(trials, inputs, MIN_PREFIX_S if min_prefix_s is None else min_prefix_s)

    evals = Evaluations(out, executor, force=force, progress=progress)
    ranked = halving(every, inputs, fractions, evals, goal, mark=True)
    if not ranked or ranked[0][1].error is not None:
        why = ranked[0][1].error if ranked else next((t.refused for t in every if t.refused), "no trial")
        raise DatmoError(f"no trial was scored: {why}")
    best, best_score = ranked[0]
    scores = {t.index: evals.score(t, inputs, fractions[max(t.rung, 0)], goal) for t in every}
    start_score = scores[0]
    folds = []
    if cv:
        for held in inputs:
            train = [log for log in inputs if log is not held]
            fold_best, fold_score = halving(every, train, fractions, evals, goal, tag=f"without {held.name}: ")[
                0
            ]  # the tune's prefixes
            evals.need([(fold_best, held, held.scans)])
            on_held = evals.score(fold_best, [held], 1.0, goal)
            folds.append(Fold(held.name, fold_best.index, fold_score.value, on_held.value))
    return TuneResult(
        out, goal, dims, inputs, every, scores, fractions, best, best_score, start_score, folds, evals.ran, evals.reused
    )


__all__ = ["Constraint", "Fold", "TuneResult", "run_tune"]
