"""Segmentation and features on every real log in ../shared/data (CARMEN logs, the Killian g2o file, the
legtracker bags with all their scan topics): they run, and the results keep their invariants."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from datmo_cli.log.importers import import_log
from datmo_cli.perception.features import extract_run

CARMEN = ["acapulco", "aces", "belgioioso", "csail", "edmonton", "fhw", "freiburg-079", "freiburg-101",
          "freiburg-campus", "infinite-corridor", "intel", "orebro", "seattle"]
BAGS = [("demo_stationary_simple_environment.bag", None), ("negative_2.bag", "/left_scan"),
        ("negative_2.bag", "/right_scan"), ("negative_2.bag", "/rear_scan")] + \
       [(f"positive_{k}_extracted.bag", None) for k in (1, 2, 3, 4, 6, 7)]


def check(path, topic=None, max_scans=None, lines_expected=True):
    imported = import_log(path, topic, max_scans=max_scans)
    run = imported.run
    f = extract_run(run, odometry=imported.odometry)
    n = len(run)
    for off in (f.seg_offsets, f.line_offsets, f.circle_offsets, f.blob_offsets):
        assert len(off) == n + 1 and np.all(np.diff(off) >= 0)
    assert np.all(f.lines["length"] > 0.1) and np.all(f.lines["r_acc"] > 0.5)
    assert np.all(np.isfinite(f.circles["x"])) and np.all(f.circles["radius"] > 0)
    if lines_expected:
        assert len(f.lines) > n   # indoor logs: walls in (nearly) every scan
    if imported.odometry is not None:
        assert f.landmark_frame == imported.odometry.frame_id
    return f


@pytest.mark.parametrize("name", CARMEN)
def test_carmen_logs(name):
    check(shared_path("carmen", f"{name}-corrected.log.gz"))


def test_killian_g2o():
    check(shared_path("killian", "killian.g2o.gz"))


@pytest.mark.parametrize("bag, topic", BAGS)
def test_legtracker_bags(bag, topic):
    check(shared_path("legtracker", bag), topic)
