"""Real data with the paper's rule (--leg-model paper): the legtracker demo bag (still Hokuyo, 512 beams, people
walking past) gives person tracks and no confirmed people or dynamic tracks on the walls; labelled legs are
mostly covered. The learned detector's figures on the same bags are in test_people_real.py."""

from __future__ import annotations

import pytest
from conftest import shared_path

pytestmark = [pytest.mark.unit, pytest.mark.slow, pytest.mark.shared]


def _accuracy_module():
    from benchmarks import accuracy_tracking

    return accuracy_tracking


def test_demo_bag_people_and_no_walls():
    path = shared_path("legtracker", "demo_stationary_simple_environment.bag")
    figures = _accuracy_module().demo_figures(path, {"leg_model": "paper"})
    assert figures["people"] >= 3  # 4 now
    assert figures["on_walls"] == 0


def test_positive_bags_legs_mostly_covered():
    lines = _accuracy_module().positive_lines({"leg_model": "paper"})
    if not lines:
        pytest.skip("no positive_*_extracted.bag")
    share = float(lines[-1].split(": ")[1].split(" of ")[0])
    # 0.752 now; it moves with small perception and tracking changes: on positive_4 one person track either
    # lives on (0.95 of its legs covered) or is lost (0.58-0.66), e.g. with the corner split of
    # line_subsegments or which of two duplicate tracks is kept
    assert share >= 0.72
