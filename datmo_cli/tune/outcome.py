"""What a tune found (`TuneResult`) and one fold of --cv (`Fold`); figures as tune.objective names them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .search import Goal, Score, Trial
from .space import Dimension
from .trial import LogInput


@dataclass
class Fold:
    """One fold of --cv: the log held out, the best trial of the tune on the others, its objective there (the
    tuned figure) and on the held-out log."""

    held_out: str
    best: int
    tuned: float | None
    held_out_value: float | None


@dataclass
class TuneResult:
    """What a tune found: its trials (each with its score at its last rung: on the whole logs for those that
    reached it), the best, the start's score on the whole logs, the folds of --cv, and where the outputs are."""

    out_dir: Path
    goal: Goal
    dims: list[Dimension]
    logs: list[LogInput]
    trials: list[Trial]
    scores: dict[int, Score]  # trial index -> its score at its last rung
    fractions: list[float]
    best: Trial
    best_score: Score
    start_score: Score
    folds: list[Fold] = field(default_factory=list)
    ran: int = 0
    reused: int = 0
    outputs: list[Path] = field(default_factory=list)
