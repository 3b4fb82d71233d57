"""Real data: the legtracker demo bag (still Hokuyo, 512 beams, people walking past) gives person tracks
and no confirmed people or dynamic tracks on the walls; labelled legs are mostly covered."""

from __future__ import annotations

import importlib.util

import pytest
from conftest import ROOT, shared_path

HAVE_PERCEPTION = importlib.util.find_spec("datmo_cli.perception.features") is not None
pytestmark = [pytest.mark.slow, pytest.mark.shared,
              pytest.mark.skipif(not HAVE_PERCEPTION, reason="datmo_cli.perception.features absent")]


def _accuracy_module():  # noqa: ANN202
    spec = importlib.util.spec_from_file_location("accuracy_tracking", ROOT / "benchmarks" / "accuracy_tracking.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_demo_bag_people_and_no_walls():
    path = shared_path("legtracker", "demo_stationary_simple_environment.bag")
    figures = _accuracy_module().demo_figures(path)
    assert figures["people"] >= 1
    assert figures["on_walls"] == 0
