"""Tracking accuracy (make accuracy): CLEAR-MOT, IDF1 and HOTA on the simulated sample logs, class accuracy,
the platform through the column occlusion, the static scene, and the legtracker bags (real data).

Each simulated log is tracked twice: from datmo's own features (segmentation + Hough, the real pipeline)
and from ideal features built from the ground truth (what a perfect perception would give), so the
tracker's own share of the error shows.
"""

from __future__ import annotations

import importlib.util
import time
import warnings
from pathlib import Path

import numpy as np

from benchmarks import tracking_scoring as acc
from benchmarks.common import print_lines
from datmo_cli import evaluate as ev
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.logs.vocabulary import CLASS_CIRCLE_OBJECT, CLASS_PERSON, MOBILITY_DYNAMIC, STATUS_CONFIRMED
from datmo_cli.passes.stages import run_features, track_run
from datmo_cli.report import decode_channel

ROOT = Path(__file__).resolve().parent.parent
LOGS = ROOT / "sample_logs"
LEGTRACKER = ROOT.parent / "shared" / "data" / "legtracker"


def learned_legs(feature_params: dict | None) -> bool:
    """Whether features made with these FeatureParams overrides come with a leg detector's legs."""
    return (feature_params or {}).get("leg_model", "default") != "paper"


def have_perception() -> bool:
    return importlib.util.find_spec("datmo_cli.perception.features") is not None


def load_sim(name: str):
    log = mcapio.read_log(LOGS / f"{name}.mcap", topics=None)
    run = mcapio.run_from_log(log)
    truth = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    return run, mcapio.odometry_from_log(log), truth


def score_sim(name: str, source: str, feature_params: dict | None = None) -> dict:
    """Scores of one simulated log with features from `source` ("datmo", "ideal" or "degraded");
    `feature_params`: FeatureParams overrides for "datmo" (None: perception's defaults)."""
    run, odom, truth = load_sim(name)
    gt_off, gt = truth.offsets["objects"], truth.items["objects"]
    if source in ("ideal", "degraded"):
        feats = acc.ideal_features(
            gt_off,
            gt,
            np.random.default_rng(0),
            noise=0.01 if source == "ideal" else 0.02,
            degraded=source == "degraded",
        )
    else:
        feats = run_features(run, odom, feature_params)
    t0 = time.perf_counter()
    tracked = track_run(
        run, feats, odometry=odom, markers=False, learned=source == "datmo" and learned_legs(feature_params)
    )
    seconds = time.perf_counter() - t0
    off, items = tracked.all_tracks()
    g, regions, hy = ev.frames_from_channels(
        truth.stamps, gt_off, gt, truth.scalars.get("sensor_theta"), tracked.stamps, off, items
    )
    scores = ev.evaluate(g, hy, regions=regions)
    tid, tcls, gid, gcls = acc.matched_targets(gt_off, gt, off, items)
    out = {
        "scores": scores,
        "class_accuracy": acc.class_accuracy(tcls, gcls, gid),
        "seconds": seconds,
        "scans": len(run),
    }
    dyn = items[(items["status"] == STATUS_CONFIRMED) & (items["mobility"] == MOBILITY_DYNAMIC)]
    out["confirmed_dynamic_tracks"] = len(np.unique(dyn["id"]))
    platforms = np.unique(gt["id"][gt["classification"] == CLASS_CIRCLE_OBJECT])
    if len(platforms):
        pid = int(platforms[0])
        on = gid == pid
        out["platform_switches"] = acc.id_switches(tid, gid, pid)
        out["platform_as_circle"] = float(np.mean(tcls[on] == CLASS_CIRCLE_OBJECT)) if on.any() else None
    return out


def _fmt(v: object) -> str:
    return "n/a" if v is None else f"{v:.3f}" if isinstance(v, float) else str(v)


def sim_lines(source: str, feature_params: dict | None = None) -> list[str]:
    lines = []
    for name in ("hall", "crowd6", "corridor", "patrol", "static"):
        if not (LOGS / f"{name}.mcap").exists():
            lines.append(f"{name}: log missing")
            continue
        r = score_sim(name, source, feature_params)
        s = r["scores"]
        people = s.get("person", {})
        line = (
            f"{name:9s} people MOTA {_fmt(people.get('mota'))} IDF1 {_fmt(people.get('idf1'))} "
            f"HOTA {_fmt(people.get('hota'))} switches {people.get('num_switches', 'n/a')} | "
            f"all MOTA {_fmt(s['all']['mota'])} IDF1 {_fmt(s['all']['idf1'])} HOTA {_fmt(s['all']['hota'])} "
            f"(DetA {_fmt(s['all']['deta'])}, AssA {_fmt(s['all']['assa'])}) | "
            f"class right {_fmt(r['class_accuracy'])}"
        )
        if "platform_switches" in r and name == "hall":
            line += (
                f" | platform: {r['platform_switches']} id switches, circle object "
                f"{_fmt(r['platform_as_circle'])} of the time"
            )
        if name == "static":
            line += f" | confirmed dynamic tracks {r['confirmed_dynamic_tracks']}"
        lines.append(line)
    return lines


# ------------------------------------------------------------------------------------------ real data


def read_ros1_scans(path: Path, topic: str) -> tuple[ScanRun, np.ndarray]:
    """A ROS 1 bag's LaserScans on `topic` as a ScanRun (header stamps), and their bag log times (ns)."""
    from rosbags.highlevel import AnyReader

    stamps, ranges, geom, log_times = [], [], None, []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            log_times.append(log_time)
            if geom is None:
                geom = ScanGeometry(
                    float(msg.angle_min),
                    float(msg.angle_increment),
                    len(msg.ranges),
                    float(msg.range_min),
                    float(msg.range_max),
                    0.0,
                    0.0,
                    msg.header.frame_id,
                )
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            ranges.append(np.asarray(msg.ranges, np.float32))
    return ScanRun(np.array(stamps, np.int64), np.stack(ranges), geom), np.array(log_times, np.int64)


def read_leg_labels(path: Path, scan_log_times: np.ndarray) -> list[np.ndarray]:
    """The labelled leg positions (/leg_cluster_positions, laser frame) of each scan: the labels have no
    header stamp, so each scan takes the label message logged nearest to it (within 50 ms)."""
    from rosbags.highlevel import AnyReader

    times, labels = [], []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == "/leg_cluster_positions"]
        for conn, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            times.append(log_time)
            labels.append(np.array([[p.position.x, p.position.y] for p in msg.poses]).reshape(-1, 2))
    if not times:
        return [np.zeros((0, 2)) for _ in scan_log_times]
    times = np.array(times, np.int64)
    out = []
    for t in scan_log_times.tolist():
        j = int(np.argmin(np.abs(times - t)))
        out.append(labels[j] if abs(int(times[j]) - t) <= 50_000_000 else np.zeros((0, 2)))
    return out


def demo_figures(path: Path, feature_params: dict | None = None) -> dict:
    """On the still-scanner demo bag: scans, confirmed person tracks, and confirmed person or dynamic
    tracks that stay on the background (the per-beam median range: walls) and within 0.5 m all along."""
    run, _ = read_ros1_scans(path, "/scan")
    feats = run_features(run, None, feature_params)
    tracked = track_run(run, feats, markers=False, learned=learned_legs(feature_params))
    off, items = tracked.all_tracks()
    conf = items[items["status"] == STATUS_CONFIRMED]
    people = np.unique(conf["id"][conf["classification"] == CLASS_PERSON])
    # walls: with a still scanner, the per-beam median range over the run is the background
    # beams that never return have no background (NaN: nothing is near it)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        background = np.nanmedian(np.where(np.isfinite(run.ranges), run.ranges, np.nan), axis=0)
    rng = np.hypot(conf["x"], conf["y"])
    beam = np.clip(
        np.rint((np.arctan2(conf["y"], conf["x"]) - run.geometry.angle_min) / run.geometry.angle_increment).astype(int),
        0,
        run.geometry.n_beams - 1,
    )
    near = np.abs(rng - background[beam]) < 0.25
    suspect = (conf["mobility"] == MOBILITY_DYNAMIC) | (conf["classification"] == CLASS_PERSON)
    wall_dynamic = []  # tracks that stay on the background all their life: walls, not passers-by
    for i in np.unique(conf["id"][suspect]).tolist():
        mine = conf["id"] == i
        span = np.hypot(np.ptp(conf["x"][mine]), np.ptp(conf["y"][mine]))
        if near[mine].all() and span < 0.5:
            wall_dynamic.append(i)
    return {"scans": len(run), "people": len(people), "on_walls": len(wall_dynamic)}


def demo_lines(feature_params: dict | None = None) -> list[str]:
    path = LEGTRACKER / "demo_stationary_simple_environment.bag"
    if not path.exists():
        return [f"{path}: absent"]
    f = demo_figures(path, feature_params)
    return [
        f"demo_stationary: {f['scans']} scans, {f['people']} person tracks confirmed, "
        f"{f['on_walls']} confirmed person/dynamic tracks on the walls"
    ]


def positive_lines(feature_params: dict | None = None) -> list[str]:
    out, hit_all, total_all = [], 0, 0
    for path in sorted(LEGTRACKER.glob("positive_*_extracted.bag")):
        run, log_times = read_ros1_scans(path, "/training_scan")
        legs = read_leg_labels(path, log_times)
        feats = run_features(run, None, feature_params)
        tracked = track_run(run, feats, markers=False, learned=learned_legs(feature_params))
        hit, total = acc.leg_coverage(legs, [f.circles for f in feats], tracked.tracks)
        hit_all, total_all = hit_all + hit, total_all + total
        out.append(
            f"{path.name}: {hit}/{total} labelled legs in a leg circle or person track ({hit / max(total, 1):.3f})"
        )
    if total_all:
        out.append(f"all positive bags: {hit_all / total_all:.3f} of {total_all} labelled legs")
    return out


def main() -> None:
    print_lines("Tracking accuracy with ideal features from ground truth (the tracker alone)", sim_lines("ideal"))
    print_lines(
        "... with degraded ideal features (hidden and merged legs, 5 % missed, 2 cm noise)", sim_lines("degraded")
    )
    if not have_perception():
        print_lines("Tracking accuracy with datmo features", ["skipped: datmo_cli.perception.features is absent"])
        return
    targets = (
        "targets: hall people MOTA >= 0.90, IDF1 >= 0.85; crowd6 MOTA >= 0.75; class right >= 0.95; "
        "static: no confirmed dynamic track"
    )
    print_lines(f"Tracking accuracy with datmo features, perception defaults ({targets})", sim_lines("datmo"))
    if LEGTRACKER.exists():
        print_lines("Real data: legtracker bags, perception defaults", demo_lines() + positive_lines())


if __name__ == "__main__":
    main()
