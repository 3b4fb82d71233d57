"""`datmo tune`: the parameters that fit a user's scanner and rooms, found on logs with ground truth.

A space file (tune.space) names parameters with ranges or choices; trial 0 is the start (the defaults, or
--config), the other trials quasi-random settings of the space (a scrambled Sobol sequence of the seed). Each
trial is scored as `datmo run` + `datmo evaluate` score it (tune.trial), its objective a figure evaluate prints,
averaged over the logs, with optional constraints (tune.objective). Successive halving (tune.search) scores
every trial on the first third of each log, then the best third of them on the whole logs, and so on with more
rungs for more trials; every evaluation is a batch task (local processes, or a Dask cluster) recorded in
DIR/manifest.jsonl, so a tune resumes, and the same seed gives the same trials and best anywhere. The outputs
(tune.results): DIR/trials.parquet, DIR/best.toml, DIR/tune.png; with --cv, leave-one-log-out folds.

The modules: space, objective, trial (one evaluation: a batch task; the logs' prefixes), search (settings,
rungs, the evaluations and their ledger, halving), outcome (TuneResult), results (outputs and the table),
runner (run_tune).
"""

from .outcome import Fold, TuneResult
from .runner import run_tune
from .search import TuneInterrupted

__all__ = ["Fold", "TuneInterrupted", "TuneResult", "run_tune"]
