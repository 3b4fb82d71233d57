"""Segmentation, features and landmarks on every real log in ../shared/data: the CARMEN logs, the Killian g2o
file and every LaserScan topic of the legtracker bags (scanners of 180 to 768 beams, 0.35° to 1° steps). All
scans of every log (about 25,000 in all) take a few seconds, so none of this is marked slow."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path

from datmo_cli.logs import mcapio
from datmo_cli.logs.importers import import_log
from datmo_cli.passes.stages import derive_features
from datmo_cli.perception.features import extract_run, segment_run
from datmo_cli.perception.params import FeatureParams

pytestmark = [pytest.mark.unit, pytest.mark.shared]

CARMEN = [
    "acapulco",
    "aces",
    "belgioioso",
    "csail",
    "edmonton",
    "fhw",
    "freiburg-079",
    "freiburg-101",
    "freiburg-campus",
    "infinite-corridor",
    "intel",
    "orebro",
    "seattle",
]
BAGS = [
    "demo_stationary_simple_environment",
    "negative_2",
    "positive_1_extracted",
    "positive_2_extracted",
    "positive_3_extracted",
    "positive_4_extracted",
    "positive_6_extracted",
    "positive_7_extracted",
]
LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan", "sensor_msgs/LaserScan")


def check_offsets(offsets: np.ndarray, n_scans: int, n_items: int) -> None:
    assert len(offsets) == n_scans + 1
    assert offsets[0] == 0 and offsets[-1] == n_items
    assert np.all(np.diff(offsets) >= 0)


def check(path, topic=None, walls=True):
    """Extract every scan of the log at `path` and check the results' invariants; returns the features."""
    imported = import_log(path, topic)
    run, odom = imported.run, imported.odometry
    n, beams = len(run), run.geometry.n_beams
    assert n > 0
    f = extract_run(run, odometry=odom)
    assert len(f) == n
    check_offsets(f.seg_offsets, n, len(f.seg_start))
    check_offsets(f.line_offsets, n, len(f.lines))
    check_offsets(f.circle_offsets, n, len(f.circles))
    check_offsets(f.blob_offsets, n, len(f.blobs))
    assert np.all(f.seg_start < f.seg_end) and np.all(f.seg_end <= beams)
    # segment_run gives the segments extract_run worked on
    start, end, offsets = segment_run(run)
    assert np.array_equal(start, f.seg_start) and np.array_equal(end, f.seg_end)
    assert np.array_equal(offsets, f.seg_offsets)
    p = FeatureParams()
    lines = f.lines
    assert np.all(lines["length"] > p.line_min_length)
    assert np.all(lines["r_acc"] > p.line_min_racc) and np.all(lines["r_acc"] <= 1.0 + 1e-6)
    assert np.all(lines["first"] <= lines["last"]) and np.all(lines["last"] < beams)
    for name in ("x_ini", "y_ini", "x_end", "y_end", "rho", "theta"):
        assert np.all(np.isfinite(lines[name])), name
    assert np.all(np.isfinite(f.circles["x"])) and np.all(np.isfinite(f.circles["y"]))
    # the least-squares fit may refine a Hough radius to 0.8 x the smallest .. 1.2 x the largest one voted for
    assert np.all(f.circles["radius"] >= 0.8 * p.circle_radius_min - 1e-4)
    assert np.all(f.circles["radius"] <= 1.2 * p.circle_radius_max + 1e-4)
    assert np.all(np.isfinite(f.blobs["x"])) and np.all(np.isfinite(f.blobs["y"]))
    counts = f.counts()
    assert all(np.isfinite(v) and v >= 0 for v in counts.values())
    if walls:
        assert counts["lines"] > 1.0  # indoor logs: walls in nearly every scan
    db = f.landmarks.final()
    assert np.all(np.isfinite(db["x"])) and np.all(np.isfinite(db["y"]))
    check_offsets(f.landmarks.snap_offsets, n, len(f.landmarks.snap_idx))
    if odom is not None and len(odom):
        assert f.landmark_frame == odom.frame_id
    else:
        assert f.landmark_frame == run.geometry.frame_id
    # the channels `datmo features` writes, on the first scans
    head = run.slice(0, min(n, 50))
    channels, _ = derive_features(head, odometry=odom)
    for topic_name in (
        mcapio.TOPIC_SEGMENTS,
        mcapio.TOPIC_FEATURES,
        mcapio.TOPIC_LANDMARKS,
        mcapio.TOPIC_MARKERS_FEATURES,
    ):
        _, stamps, payloads = channels[topic_name]
        assert len(stamps) == len(payloads) == len(head)
    return f


@pytest.mark.parametrize("name", CARMEN)
def test_carmen_log(name):
    f = check(shared_path("carmen", f"{name}-corrected.log.gz"))
    assert len(f.landmarks.final()) > 0


def test_killian_g2o():
    f = check(shared_path("killian", "killian.g2o.gz"))
    assert len(f.landmarks.final()) > 0


def scan_topics(bag) -> list[str]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return sorted({c.topic for c in reader.connections if c.msgtype in LASERSCAN_TYPES})


@pytest.mark.parametrize("name", BAGS)
def test_legtracker_bag_every_scan_topic(name):
    bag = shared_path("legtracker", f"{name}.bag")
    topics = scan_topics(bag)
    assert topics, f"{bag}: no LaserScan topic"
    for topic in topics:
        check(bag, topic)


def test_every_shared_log_is_covered():
    """A log added to ../shared/data must be added to the lists above."""
    carmen = sorted(p.name for p in shared_path("carmen").glob("*.log.gz"))
    assert carmen == sorted(f"{n}-corrected.log.gz" for n in CARMEN)
    assert sorted(p.stem for p in shared_path("legtracker").glob("*.bag")) == sorted(BAGS)
    assert [p.name for p in shared_path("killian").glob("*.g2o.gz")] == ["killian.g2o.gz"]
