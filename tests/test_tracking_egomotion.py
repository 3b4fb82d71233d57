"""A log without odometry whose scanner moves is tracked in poses from scan matching (ego-motion), which the
output holds on /odom (frame scan_odom); a still scanner's log is tracked in its sensor frame, as before."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.perception.egomotion import FRAME_ID, odometry_for, scans_move
from datmo_cli.sim.simulate import simulate_scene

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def patrol():
    return simulate_scene("patrol", duration=8.0)


@pytest.fixture(scope="module")
def hall():
    return simulate_scene("hall", duration=8.0)


def test_moving_scanner_gets_estimated_poses_and_a_still_one_none(patrol, hall):
    assert scans_move(patrol.run) and not scans_move(hall.run)
    odom, estimated = odometry_for(patrol.run, None, "auto")
    assert estimated and odom.frame_id == FRAME_ID and len(odom) == len(patrol.run)
    truth = patrol.odometry.at(patrol.run.stamps)
    moved = np.hypot(*(truth[-1, :2] - truth[0, :2]))
    assert abs(np.hypot(odom.x[-1] - odom.x[0], odom.y[-1] - odom.y[0]) - moved) < 0.1
    assert odometry_for(hall.run, None, "auto") == (None, False)
    forced, estimated = odometry_for(hall.run, None, "on")
    assert estimated and np.hypot(forced.x, forced.y).max() < 0.05  # a still scanner stays put
    assert odometry_for(patrol.run, None, "off") == (None, False)
    assert odometry_for(patrol.run, patrol.odometry, "on") == (patrol.odometry, False)  # the log's own wins
    with pytest.raises(ValueError, match="not one of"):
        odometry_for(patrol.run, None, "sometimes")


def test_track_writes_the_estimated_odometry_and_world_positions(patrol, hall, tmp_path):
    for name, sim, moving in (("patrol", patrol, True), ("hall", hall, False)):
        src, out = tmp_path / f"{name}.mcap", tmp_path / f"{name}-tracks.mcap"
        with mcapio.LogWriter(src) as w:
            w.write_scans(sim.run)  # no /odom
        r = CliRunner().invoke(cli, ["track", str(src), "-o", str(out)])
        assert r.exit_code == 0, r.output
        log = mcapio.read_log(out, topics=None)
        assert log.has(mcapio.TOPIC_ODOM) == moving
        if moving:
            odom = mcapio.odometry_from_log(log)
            assert odom.frame_id == FRAME_ID and len(odom) == len(sim.run)
        r = CliRunner().invoke(
            cli, ["track", str(src), "-o", str(tmp_path / f"{name}-off.mcap"), "--ego-motion", "off"]
        )
        assert r.exit_code == 0, r.output
        assert not mcapio.read_log(tmp_path / f"{name}-off.mcap", topics=None).has(mcapio.TOPIC_ODOM)
