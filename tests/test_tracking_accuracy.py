"""Tracking accuracy on the simulated sample logs (bounds looser than make accuracy's targets).

With ideal features built from the ground truth these check the tracker alone (degraded: with hidden and
merged legs and missed detections); with datmo's own features (segmentation + Hough, perception's default
FeatureParams) the whole pipeline: "datmo" with the learned leg detector, "paper" with the paper's rule.
The datmo and paper bounds sit a little below what the pipeline reaches now (below make accuracy's targets,
which it does not meet yet): they guard against regressions.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import tracking_scoring as acc
from datmo_cli import evaluate as ev
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.vocabulary import CLASS_CIRCLE_OBJECT, CLASS_PERSON, STATUS_CONFIRMED
from datmo_cli.passes.stages import run_features, track_run
from datmo_cli.report import decode_channel

pytestmark = pytest.mark.unit


def _score(sample_logs, name: str, source: str) -> dict:
    log = mcapio.read_log(sample_logs / f"{name}.mcap", topics=None)
    run, odom = mcapio.run_from_log(log), mcapio.odometry_from_log(log)
    truth = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    off, gt = truth.offsets["objects"], truth.items["objects"]
    if source in ("datmo", "paper"):
        feats = run_features(run, odom, None if source == "datmo" else {"leg_model": "paper"})
    else:
        feats = acc.ideal_features(
            off, gt, np.random.default_rng(0), noise=0.01 if source == "ideal" else 0.02, degraded=source == "degraded"
        )
    tracked = track_run(run, feats, odometry=odom, markers=False, learned=source == "datmo")
    toff, items = tracked.all_tracks()
    g, regions, hy = ev.frames_from_channels(
        truth.stamps, off, gt, truth.scalars.get("sensor_theta"), tracked.stamps, toff, items
    )
    tid, tcls, gid, gcls = acc.matched_targets(off, gt, toff, items)
    platform = np.unique(gt["id"][gt["classification"] == CLASS_CIRCLE_OBJECT])
    return {
        "scores": ev.evaluate(g, hy, regions=regions),
        "class": acc.class_accuracy(tcls, gcls, gid),
        "platform_switches": acc.id_switches(tid, gid, int(platform[0])) if len(platform) else 0,
        "dynamic": len(np.unique(items["id"][(items["status"] == 1) & (items["mobility"] == 1)])),
        "people": len(
            np.unique(items["id"][(items["status"] == STATUS_CONFIRMED) & (items["classification"] == CLASS_PERSON)])
        ),
    }


SOURCES = ["ideal", "degraded", "datmo", "paper"]
# (people MOTA, people IDF1, class right, platform id switches, circle object switches) bounds per source:
# the tracker alone must do better
HALL = {
    "ideal": (0.90, 0.90, 0.95, 0, 0),
    "degraded": (0.85, 0.85, 0.93, 0, 0),
    "datmo": (0.75, 0.42, 0.91, 14, 14),  # now 0.797/0.470, class 0.940, platform 11 switches
    "paper": (0.68, 0.55, 0.87, 6, 6),
}  # now 0.728/0.603, class 0.902, platform 4 switches
CROWD = {"ideal": 0.85, "degraded": 0.80, "datmo": 0.86, "paper": 0.82}  # datmo now 0.899
STATIC_DYNAMIC = {"ideal": 0, "degraded": 0, "datmo": 0, "paper": 0}  # confirmed dynamic or person tracks


@pytest.mark.slow
@pytest.mark.parametrize("source", SOURCES)
def test_hall(sample_logs, source):
    r = _score(sample_logs, "hall", source)
    people = r["scores"]["person"]
    mota, idf1, cls, platform_switches, circle_switches = HALL[source]
    assert people["mota"] >= mota and people["idf1"] >= idf1
    assert r["class"] >= cls
    assert r["platform_switches"] <= platform_switches
    assert r["scores"]["circle object"]["num_switches"] <= circle_switches


@pytest.mark.slow
@pytest.mark.parametrize("source", SOURCES)
def test_crowd_and_static(sample_logs, source):
    assert _score(sample_logs, "crowd6", source)["scores"]["person"]["mota"] >= CROWD[source]
    static = _score(sample_logs, "static", source)
    assert static["dynamic"] <= STATIC_DYNAMIC[source] and static["people"] <= STATIC_DYNAMIC[source]


@pytest.mark.slow
def test_moving_sensor_tracks_in_the_world_frame(sample_logs):
    """patrol.mcap has /odom: people are tracked in the world frame while the scanner drives and turns."""
    r = _score(sample_logs, "patrol", "ideal")
    assert r["scores"]["person"]["mota"] >= 0.7
    assert r["class"] >= 0.8
