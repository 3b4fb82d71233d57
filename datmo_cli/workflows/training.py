"""`datmo train-legs`' work as a call (datmo_cli.api.train_legs): the learned leg detector (perception.training)
trained on labelled recordings (LaserScans with a geometry_msgs/PoseArray of the legs in each scan, laser
frame, metres) and empty ones, its held-out figures estimated, the model written with its provenance. The
command keeps what it prints: the table of figures and the summary line."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..perception.training import TrainingResult

LABELS_TOPIC = "/leg_cluster_positions"


@dataclass
class LegTraining:
    """A trained leg model: `output` (the .npz written), `result` (the TrainingResult: .model, .held_out,
    .mean, .threshold, .tables) and the `labelled` and `empty` recordings it learned from."""

    output: Path
    result: TrainingResult
    labelled: int
    empty: int

    @property
    def summary(self) -> str:
        """The line `datmo train-legs` says: the model, its threshold and what it was trained on."""
        r = self.result
        n_legs = sum(int(t.label.sum()) for t in r.tables)
        n_seg = sum(len(t) for t in r.tables)
        return (
            f"{self.output}: {r.model.n_trees} trees, threshold {r.threshold:.2f}; trained on {n_seg:,} "
            f"segments ({n_legs:,} legs) of {self.labelled} labelled and {self.empty} empty recordings"
        )


def train_legs(
    positives: Sequence[str | os.PathLike],
    negatives: Sequence[str | os.PathLike],
    output: str | os.PathLike,
    *,
    topic: str | None = None,
    labels_topic: str = LABELS_TOPIC,
    force: bool = False,
    with_simulated: bool = False,
    on_trained: Callable[[TrainingResult], None] | None = None,
) -> LegTraining:
    """`datmo train-legs --positive ... --negative ... -o OUTPUT`: read the labelled files `positives` (ROS 1
    bags, ROS 2 bag folders or MCAP files; `topic` their LaserScan topic, None: the only one; `labels_topic`
    the legs) and the empty `negatives` (every LaserScan topic one empty recording), with `with_simulated`
    also simulated LMS200 recordings; train, estimate the held-out figures (none with one positive), call
    `on_trained(result)`, then write the model to `output` (an existing file only with `force`). A progress
    bar on stderr in a terminal. Needs scikit-learn (the train extra). Returns the LegTraining."""
    from ..base.errors import InputError
    from ..base.outputs import check_output
    from ..base.progress import bar
    from ..perception import training as TR

    pos, neg, output = [Path(p) for p in positives], [Path(n) for n in negatives], Path(output)
    check_output(output, force=force, inputs=[*pos, *neg], what="model")  # before the training
    if not pos:
        raise InputError("no labelled file: give at least one with --positive")
    _labelled_or_empty(pos, neg)
    TR.require_sklearn()
    with bar("reading", len(pos) + len(neg), unit="steps") as shown:
        labelled, empty = [], []
        for i, p in enumerate(pos):
            labelled.append(TR.read_labelled(p, topic, labels_topic))
            shown.update(i + 1)
        for i, p in enumerate(neg):
            empty.extend(TR.read_empty(p))
            shown.update(len(pos) + i + 1)

        def progress(stage: str, done: int, total: int) -> None:
            shown.update(done, total, description=stage)

        extra = []
        if with_simulated:
            from ..passes.simulated import simulated_recordings

            shown.update(0, description="simulating")
            extra = simulated_recordings()
        result = TR.train_leg_model(labelled, empty, progress=progress, labels_topic=labels_topic, extra=extra)
    if on_trained is not None:
        on_trained(result)
    result.model.save(output, force=force)  # checked again: it may have appeared while training
    return LegTraining(output, result, len(labelled), len(empty))


def _labelled_or_empty(positives: Sequence[Path], negatives: Sequence[Path]) -> None:
    """InputError when a --negative file is a --positive file too (the same file, a link to it or a copy of
    it): its legs would be taught as both legs and not legs, and the model would find none."""
    from ..base.errors import InputError

    for n in negatives:
        for p in positives:
            if _same_data(n, p):
                also = "" if str(n) == str(p) else f" (as {p})"
                raise InputError(
                    f"{n}: given as --negative and as --positive{also}; a recording is either labelled "
                    "or empty of people"
                )


def _same_data(a: Path, b: Path) -> bool:
    """Whether two existing paths hold the same data: one file (or folder), or byte-identical copies."""
    from ..logs.mcapio import sha256_of

    try:
        if os.path.samefile(a, b):
            return True
        if a.is_dir() != b.is_dir() or (a.is_file() and a.stat().st_size != b.stat().st_size):
            return False
        return sha256_of(a) == sha256_of(b)
    except OSError:  # a missing or unreadable file: reading it says so
        return False
