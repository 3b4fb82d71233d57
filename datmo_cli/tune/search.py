"""The search of `datmo tune`: settings drawn from the space (search.settings), scored by successive halving
(every setting on a prefix of each log, the best third on longer prefixes, the last rung on the whole logs),
every evaluation a batch task run once and kept in DIR/manifest.jsonl (`Evaluations`), so an interrupted tune
continues where it stopped and a finished one costs nothing to run again.

An evaluation is one setting on one log's first `scans` scans; its key is the setting's parameters' hash
(batch.params_hash), the log's SHA-256 and the scans, so two tunes (or the folds of --cv) share what they have
in common. Rankings break ties by trial number: the same seed gives the same trials and best on any executor.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .. import __version__
from ..base.errors import ConfigError, DatmoError
from ..batch.manifest import DONE, FAILED, Manifest, manifest_line
from ..batch.task import RunOptions
from .objective import Constraint, mean
from .trial import EvalTask, LogInput, prefix_log, prefix_scans

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig

ETA = 3  # successive halving keeps the best 1/ETA of the settings from one rung to the next
MIN_PREFIX_S = 15.0  # the shortest prefix a rung scores, seconds of the shortest log
WORK = ".work"  # DIR/.work: the evaluations' temporary outputs and the logs' prefixes


class TuneInterrupted(DatmoError):
    """Ctrl-C: the evaluations finished so far are in the manifest; the same command continues."""

    exit_code = 130


@dataclass
class Trial:
    """A setting: `values` of the space's keys, its DatmoConfig (None: refused, `refused` says why) and its
    parameters' hash."""

    index: int
    values: dict[str, object]
    config: DatmoConfig | None
    hash: str = ""
    refused: str | None = None
    rung: int = -1  # the last rung of the tune on all logs that scored it


@dataclass(frozen=True)
class Goal:
    """The objective (a figure's name; `higher`: a rise is better) and the constraints."""

    objective: str
    higher: bool
    constraints: tuple[Constraint, ...] = ()


@dataclass
class Score:
    """A trial's figures over some logs at one prefix: the objective's mean, the constraints' means, whether it
    meets them, each log's figures, the seconds its evaluations took, and the first error (failed)."""

    value: float | None = None
    constrained: dict[str, float | None] = field(default_factory=dict)
    feasible: bool = False
    per_log: dict[str, dict] = field(default_factory=dict)
    seconds: float = 0.0
    error: str | None = None


def settings(base, dims, trials: int, seed: int) -> list[Trial]:
    """Trial 0, the start (`base`, the config the tune starts from), then `trials - 1` settings of the space
    (space.samples of `seed`) applied to `base`; a setting the configuration refuses (a minimum above its
    maximum, confirm_window below confirm_hits) is a trial refused with the config's message."""
    from ..batch.task import params_hash
    from .space import samples

    values = [{d.key: base.get(d.key) for d in dims}] + samples(dims, trials - 1, seed)
    out = []
    for i, v in enumerate(values):
        changes: dict[str, dict] = {}
        for key, value in v.items():
            section, _, name = key.partition(".")
            changes.setdefault(section, {})[name] = value
        try:
            cfg = base.replace(**changes)
        except ConfigError as exc:
            out.append(Trial(i, v, None, refused=str(exc)))
            continue
        out.append(Trial(i, v, cfg, params_hash(cfg)))
    return out


def rungs(trials: int, logs: list[LogInput], min_prefix_s: float = MIN_PREFIX_S) -> list[float]:
    """The fractions of the logs each rung scores, the last 1: as many rungs as keep ETA times fewer trials
    each and the shortest log's first prefix at least `min_prefix_s` seconds."""
    shortest = min(log.seconds for log in logs)
    n = 1
    while trials >= ETA**n and shortest / ETA**n >= min_prefix_s:
        n += 1
    return [float(ETA ** -(n - 1 - r)) for r in range(n)]


class Evaluations:
    """Every evaluation of the tune in DIR: those in the manifest (done with this datmo version; none with
    `force`) and those run through `executor`, each run once; `progress(done, total, label)` counts the evaluations
    of the current call to `need`."""

    def __init__(
        self, out_dir: Path, executor, *, force: bool, progress: Callable[[int, int, str], None] | None = None
    ):
        self.out_dir = out_dir
        self.executor = executor
        self.manifest = Manifest(str(out_dir))
        self.progress = progress
        self.label = "evaluations"  # what the current evaluations are (the rung), for progress
        self.records: dict[str, dict] = {}
        if not force:
            for key, rec in self.manifest.latest().items():
                if rec["status"] == DONE and rec.get("datmo_version") == __version__ and "metrics" in rec:
                    self.records[key] = rec
        self._loaded = set(self.records)  # done before this run
        self._reused: set[str] = set()
        self.ran = 0
        self._prefixes: dict[tuple[str, int], tuple[str, str | None, float]] = {}

    def prefix(self, log: LogInput, scans: int) -> tuple[str, str | None, float]:
        """trial.prefix_log of `log`'s first `scans` scans, made (or found) once per tune."""
        key = (log.sha256, scans)
        if key not in self._prefixes:
            self._prefixes[key] = prefix_log(log, scans, self.out_dir / WORK)
        return self._prefixes[key]

    @property
    def reused(self) -> int:
        """Evaluations found done in the manifest (by an earlier run) and used by this one."""
        return len(self._reused)

    @staticmethod
    def key(trial: Trial, log: LogInput, scans: int) -> str:
        return f"{trial.hash}/{log.sha256[:16]}/{scans}"

    def get(self, trial: Trial, log: LogInput, scans: int) -> dict | None:
        return self.records.get(self.key(trial, log, scans))

    def need(self, pairs: list[tuple[Trial, LogInput, int]]) -> None:
        """Run the evaluations of `pairs` (trial, log, scans) not yet done (a trial refused has none)."""
        todo: dict[str, EvalTask] = {}
        work = self.out_dir / WORK
        for trial, log, scans in pairs:
            key = self.key(trial, log, scans)
            if trial.config is None or key in todo:
                continue
            if key in self.records:
                if key in self._loaded:
                    self._reused.add(key)
                continue
            path, gt_csv, seconds = self.prefix(log, scans)
            todo[key] = EvalTask(
                index=len(todo),
                input=key,
                output=str(work / f"{key.replace('/', '-')}.mcap"),
                force=True,
                config=trial.config,
                options=RunOptions(),
                params_hash=trial.hash,
                command_line=None,
                log=path,
                gt_csv=gt_csv,
                duration=seconds,
            )
        if not todo:
            return
        work.mkdir(parents=True, exist_ok=True)
        done = [0]
        if self.progress:
            self.progress(0, len(todo), self.label)

        def finished(rec: dict) -> None:
            if rec["status"] not in (DONE, FAILED):
                return
            self.manifest.append(manifest_line(rec))
            self.records[rec["input"]] = rec
            self.ran += 1
            done[0] += 1
            if self.progress:
                self.progress(done[0], len(todo), self.label)

        try:
            self.executor.run(list(todo.values()), finished)
        except KeyboardInterrupt:
            raise TuneInterrupted(
                f"interrupted: {len(self.records)} evaluations done and in {self.manifest.path}; "
                "run the same command again to continue"
            ) from None
        finally:
            self.manifest.close()
            for task in todo.values():
                if os.path.exists(task.output):
                    os.unlink(task.output)

    def score(self, trial: Trial, logs: list[LogInput], fraction: float, goal: Goal) -> Score:
        """`trial`'s figures on `logs` at `fraction` of each (see Score)."""
        out = Score()
        if trial.config is None:
            out.error = trial.refused
            return out
        for log in logs:
            rec = self.get(trial, log, prefix_scans(log, fraction))
            if rec is None:
                out.error = "not scored"
                return out
            out.seconds += rec.get("seconds") or 0.0
            if rec["status"] != DONE:
                out.error = rec.get("error") or "failed"
                return out
            out.per_log[log.name] = rec["metrics"]
        out.value = mean([m.get(goal.objective) for m in out.per_log.values()])
        out.constrained = {c.name: mean([m.get(c.name) for m in out.per_log.values()]) for c in goal.constraints}
        out.feasible = all(c.met(out.constrained[c.name]) for c in goal.constraints)
        return out


def rank_key(trial: Trial, score: Score, goal: Goal) -> tuple:
    """Best first: scored, meeting the constraints, defined, then the objective, then the trial number."""
    value = score.value if score.value is not None else 0.0
    return (
        score.error is not None,
        not score.feasible,
        score.value is None,
        -value if goal.higher else value,
        trial.index,
    )


def halving(
    trials: list[Trial],
    logs: list[LogInput],
    fractions: list[float],
    evals: Evaluations,
    goal: Goal,
    *,
    mark: bool = False,
    tag: str = "",
) -> list[tuple[Trial, Score]]:
    """Successive halving of `trials` on `logs`: every trial at the first fraction, then the best ceil(n / ETA**r)
    at rung r (trial 0, the start, always goes on: it is the reference). Returns the trials of the last rung with
    their scores on the whole logs, best first. `mark`: record each trial's last rung (the tune on all logs);
    `tag`: what the progress calls this search (a --cv fold)."""
    alive = [t for t in trials if t.config is not None]
    ranked: list[tuple[Trial, Score]] = []
    for r, fraction in enumerate(fractions):
        share = "the whole logs" if fraction >= 1 else f"the first 1/{round(1 / fraction)} of each log"
        evals.label = f"{tag}{len(alive)} trials on {share} (rung {r + 1} of {len(fractions)})"
        evals.need([(t, log, prefix_scans(log, fraction)) for t in alive for log in logs])
        if mark:
            for t in alive:
                t.rung = r
        ranked = sorted(
            ((t, evals.score(t, logs, fraction, goal)) for t in alive), key=lambda p: rank_key(p[0], p[1], goal)
        )
        if r + 1 < len(fractions):
            keep = math.ceil(len(trials) / ETA ** (r + 1))
            chosen = [t for t, s in ranked if s.error is None][:keep]
            alive = sorted(chosen + [t for t in alive if t.index == 0 and t not in chosen], key=lambda t: t.index)
    return ranked
