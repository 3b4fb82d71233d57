"""Every real log in ../shared/data imports with the scan counts, beam counts and angles its README states."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import shared_path

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.logs.importers import import_log

# file -> (FLASER scans, beams); angles: 181/361 span -90..+90 inclusive, 180/360 step 180/n from -90.
CARMEN = {
    "acapulco": (861, 181),
    "aces": (440, 180),
    "belgioioso": (395, 361),
    "csail": (406, 361),
    "edmonton": (340, 180),
    "fhw": (488, 180),
    "freiburg-079": (4791, 360),
    "freiburg-101": (292, 360),
    "freiburg-campus": (2008, 360),
    "infinite-corridor": (1941, 180),
    "intel": (910, 180),
    "orebro": (237, 181),
    "seattle": (241, 361),
}
LAST_ANGLE = {180: 89.0, 181: 90.0, 360: 89.5, 361: 90.0}
# file -> {topic: scans}; all /training_scan are 768 beams over 270°.
POSITIVE = {
    "positive_1": 197,
    "positive_2": 83,
    "positive_3": 175,
    "positive_4": 295,
    "positive_6": 187,
    "positive_7": 267,
}

pytestmark = [pytest.mark.cli, pytest.mark.shared]


@pytest.mark.parametrize("name", sorted(CARMEN))
def test_carmen_logs(name):
    res = import_log(shared_path("carmen", f"{name}-corrected.log.gz"))
    scans, beams = CARMEN[name]
    run = res.run
    assert (res.kind, res.topic) == ("carmen", "FLASER")
    assert run.ranges.shape == (scans, beams)
    angles = np.degrees(run.geometry.angles())
    assert angles[0] == pytest.approx(-90.0) and angles[-1] == pytest.approx(LAST_ANGLE[beams])
    assert np.all(np.diff(run.stamps) > 0)
    finite = run.ranges[np.isfinite(run.ranges)]
    assert finite.max() < run.geometry.range_max and finite.min() > 0
    assert len(res.odometry) == scans
    assert not any("malformed" in w for w in res.warnings)


def test_killian_g2o():
    res = import_log(shared_path("killian", "killian.g2o.gz"))
    run = res.run
    assert (res.kind, res.topic) == ("g2o", "ROBOTLASER1")
    assert run.ranges.shape == (3873, 180)
    g = run.geometry
    # start angle and step as printed (6 decimals): -1.570796 rad, 0.017453 rad
    assert g.angle_min == pytest.approx(-np.pi / 2, abs=1e-6)
    assert g.angle_increment == pytest.approx(np.pi / 180, abs=1e-6)
    assert g.range_max == 50.0
    assert np.all(np.diff(run.stamps) > 0) and res.warnings == []
    dt = np.median(np.diff(run.stamps)) / 1e9
    assert 1.0 < dt < 3.0  # keyframes about 1.8 s apart
    assert len(res.odometry) == 3873


def test_legtracker_demo_bag():
    res = import_log(shared_path("legtracker", "demo_stationary_simple_environment.bag"))
    run = res.run
    assert (res.kind, res.topic) == ("ros1", "/scan")
    assert run.ranges.shape == (1265, 512)
    g = run.geometry
    assert np.degrees(g.angle_min) == pytest.approx(-90.0, abs=0.01)
    assert np.degrees(g.angle_max) == pytest.approx(89.6, abs=0.1)
    assert (g.range_min, g.range_max) == pytest.approx((0.02, 5.6))
    assert (run.stamps[-1] - run.stamps[0]) / 1e9 == pytest.approx(126, abs=1.5)
    assert res.odometry is None


@pytest.mark.parametrize("name", sorted(POSITIVE))
def test_legtracker_positive_bags(name):
    path = shared_path("legtracker", f"{name}_extracted.bag")
    res = import_log(path, "/training_scan")
    assert res.run.ranges.shape == (POSITIVE[name], 768)
    fov = np.degrees(res.run.geometry.angle_increment * 768)
    assert fov == pytest.approx(270, abs=0.5)


def test_legtracker_negative_bag_has_three_scanners():
    path = shared_path("legtracker", "negative_2.bag")
    with pytest.raises(Exception, match="several sensor_msgs/LaserScan topics.*/left_scan.*/rear_scan.*/right_scan"):
        import_log(path)
    # The README says 435 scans each; the bag holds 434 on /right_scan.
    counts = {t: len(import_log(path, t).run) for t in ("/left_scan", "/rear_scan", "/right_scan")}
    assert counts == {"/left_scan": 435, "/rear_scan": 435, "/right_scan": 434}


def test_cli_import_of_real_logs_keeps_inputs(tmp_path):
    runner = CliRunner()
    for src, extra in [
        (shared_path("carmen", "csail-corrected.log.gz"), []),
        (shared_path("killian", "killian.g2o.gz"), []),
        (shared_path("legtracker", "negative_2.bag"), ["--topic", "/rear_scan"]),
    ]:
        before = hashlib.sha256(src.read_bytes()).hexdigest()
        out = tmp_path / f"{src.name}.mcap"
        result = runner.invoke(cli, ["import", str(src), "-o", str(out), *extra])
        assert result.exit_code == 0, result.output
        assert hashlib.sha256(src.read_bytes()).hexdigest() == before
        assert mcapio.summary(out).metadata["datmo.inputs"][str(src)] == before
        assert len(mcapio.read_run(out)) == import_log(src, extra[1] if extra else None).run.ranges.shape[0]
