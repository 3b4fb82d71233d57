"""The CI regression check (benchmarks/regress.py): the comparison rules, and the committed baseline."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import regress

pytestmark = pytest.mark.unit

BASE = {
    "hall": {
        "mota": 0.80,
        "motp": 0.10,
        "idf1": 0.70,
        "precision": 0.9,
        "recall": 0.85,
        "num_false_positives": 40,
        "num_misses": 60,
        "num_switches": 2,
    },
    "csail-excerpt": {"ground_truth": False, "tracks": 12, "dynamic": 3, "person": 2},
}


def with_(**changes):
    return {"hall": {**BASE["hall"], **changes}, "csail-excerpt": {**BASE["csail-excerpt"], "tracks": 99}}


def test_same_figures_pass():
    assert regress.compare(BASE, with_()) == ([], [])


@pytest.mark.parametrize(
    "changes, figure",
    [
        ({"mota": 0.779}, "mota"),
        ({"idf1": 0.67}, "idf1"),
        ({"motp": 0.125}, "motp"),
        ({"num_false_positives": 45}, "num_false_positives"),  # tolerance max(3, 10% of 40) = 4
        ({"num_switches": 6}, "num_switches"),  # tolerance 3
        ({"mota": None}, "mota is undefined"),
    ],
)
def test_a_figure_worse_than_its_tolerance_fails(changes, figure):
    failures, _ = regress.compare(BASE, with_(**changes))
    assert len(failures) == 1 and failures[0].startswith("hall: ") and figure in failures[0]


@pytest.mark.parametrize(
    "changes", [{"mota": 0.781}, {"motp": 0.119}, {"num_false_positives": 44}, {"num_switches": 5}]
)
def test_within_tolerance_passes(changes):
    assert regress.compare(BASE, with_(**changes))[0] == []


def test_improvements_are_noted_not_failed():
    failures, notes = regress.compare(BASE, with_(mota=0.9, num_misses=10))
    assert failures == [] and len(notes) == 2 and "improved" in notes[0]


def test_missing_log_fails_and_new_log_is_noted():
    current = with_()
    del current["hall"]
    current["crowd6"] = dict(BASE["hall"])
    failures, notes = regress.compare(BASE, current)
    assert failures == ["hall: no figures (the run or the evaluation failed)"]
    assert notes == ["crowd6: not in the baseline (add it with make regress-update)"]


def test_stated_tolerances_can_be_tightened():
    assert regress.compare(BASE, with_(mota=0.79), {"ratio": 0.005})[0]


def test_committed_baseline_is_well_formed():
    path = Path(regress.BASELINE)
    assert path.exists(), f"{path} is missing: make regress-update writes it"
    data = json.loads(path.read_text())
    assert set(data["tolerance"]) == set(regress.DEFAULT_TOLERANCE)
    names = {p.stem for p in regress.sample_logs()}
    assert set(data["logs"]) <= names
    for name, fig in data["logs"].items():
        if fig.get("ground_truth") is not False:
            assert set(regress.FIGURES) <= set(fig), name


@pytest.mark.slow
def test_sample_logs_hold_the_committed_baseline(capsys):
    """make regress, in the suite: datmo run and datmo evaluate on every sample log, compared with the
    committed baseline; a figure worse than its tolerance fails here."""
    code = regress.main([])
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
