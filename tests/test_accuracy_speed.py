"""benchmarks/accuracy_speed.py (make accuracy): the person speed figures on a hand-made run whose answer is
known."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import accuracy_scenes as A
from benchmarks import accuracy_speed as S
from datmo_cli.logs import cdr, types
from datmo_cli.logs.vocabulary import CLASS_PERSON, CLASS_UNKNOWN, STATUS_CONFIRMED

pytestmark = pytest.mark.unit

GT = cdr.element_dtype(types.GROUND_TRUTH_OBJECT)
TRACK = cdr.element_dtype(types.TRACK)


def hand_made() -> A.SceneRun:
    """Three scans, the sensor turned 90° (sensor_theta pi/2): a walker (id 1) going +x in the world at 1.0 m/s
    (-y in the sensor's axes), seen by a person track (7) whose velocity is off by (0.3, 0.4) m/s in scan 1; a
    second person (id 2) standing; an unknown track (9) at 3 m/s on the standing one, which is not a person and
    counts in neither figure; a person track (8) at 2.0 m/s far from everyone, the fastest person."""
    gt = np.zeros(6, GT)
    tr = np.zeros(9, TRACK)
    for k in range(3):
        g = gt[2 * k : 2 * k + 2]
        g["id"], g["classification"], g["visible"] = [1, 2], CLASS_PERSON, 1
        g["x"], g["y"] = [1.0, 3.0], [0.1 * k, 0.0]
        g["world_vx"] = [1.0, 0.0]
        t = tr[3 * k : 3 * k + 3]
        t["id"], t["status"] = [7, 9, 8], STATUS_CONFIRMED
        t["classification"] = [CLASS_PERSON, CLASS_UNKNOWN, CLASS_PERSON]
        t["x"], t["y"] = [1.0, 3.0, 9.0], [0.1 * k, 0.0, 9.0]
        t["vx"], t["vy"] = [0.3 if k == 1 else 0.0, 3.0, 2.0], [-1.0 + (0.4 if k == 1 else 0.0), 0.0, 0.0]
    off = np.array([0, 2, 4, 6]), np.array([0, 3, 6, 9])
    return A.SceneRun(off[0], gt, off[1], tr, 0.2, np.arange(3) * 200_000_000, np.full(3, np.pi / 2))


def test_speed_figures_of_a_hand_made_run():
    f = S.speed_figures(hand_made())
    assert f["rows"] == 3  # the walker's three scans; the standing person's match is no person track
    assert f["rms"] == pytest.approx(np.sqrt(0.5**2 / 3), abs=1e-6)
    assert f["median"] == pytest.approx(0.0, abs=1e-6)
    assert f["max_person"] == pytest.approx(2.0)
    assert f["fastest_walker"] == pytest.approx(1.0)
