"""People over time on real scans, held out by recording (benchmarks/accuracy_people.py): no lasting person
in empty rooms, labelled legs covered by person tracks, no person on a wall of the demo bag; and the leg
detector's held-out figures per cluster (benchmarks/accuracy_legs.py). The bounds are the figures measured
when they were written, less a small margin (see the closing notes in the issue)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT, shared_path

pytestmark = [pytest.mark.unit, pytest.mark.slow, pytest.mark.shared]

# measured with the quick fold models (a quarter of the trees): longest 7.5 / 8.9 / 27.8 s (left, right, rear
# scanner), covered 0.827, 0 on walls. The targets are 2 s, 0.90 and 0: the empty rooms and the cover are not met
# (a static pair of leg-like objects seen from the start is promoted before the background could know it)
LONGEST_EMPTY = {"/left_scan": 10.0, "/right_scan": 12.0, "/rear_scan": 30.0}  # s
COVERED = 0.80
PAPER_SHARE = 0.95  # measured 1,271 legs covered against the paper rule's 1,291 (0.98x): not ahead of it
ON_WALLS = 0


@pytest.fixture(scope="module")
def people(tmp_path_factory):
    import sys

    shared_path("legtracker", "negative_2.bag")
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from benchmarks.accuracy_people import figures

    return figures(tmp_path_factory.mktemp("folds"), quick=True)  # fold models of a quarter of the trees


def test_no_person_lasts_in_empty_rooms(people):
    for topic, (longest, _) in people["negative"]["held out"].items():
        assert longest <= LONGEST_EMPTY[topic], topic


def test_labelled_legs_are_covered_by_person_tracks(people):
    hit, total = np.sum(list(people["positive"]["held out"].values()), axis=0)
    assert total > 1000
    assert hit / total >= COVERED
    paper_hit, _ = np.sum(list(people["positive"]["paper"].values()), axis=0)
    assert hit >= PAPER_SHARE * paper_hit


def test_no_person_on_a_wall_of_the_demo_bag(people):
    demo = people["demo"]["default"]
    assert demo["on_walls"] <= ON_WALLS
    assert demo["people"] >= 3
    assert people["demo"]["paper"]["on_walls"] == 0
