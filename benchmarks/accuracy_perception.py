"""Perception accuracy (make accuracy): features and landmarks of the simulated sample logs against their
ground truth (targets: walls 1° and 2 cm; legs within 4 m 3 cm centre and 2 cm radius; columns 3 cm;
landmarks >= 95% found and <= 5% spurious on hall), synthetic scans of known geometry with σ = 1 cm range
noise, and every real log in ../shared/data (lines, circles, blobs and landmarks per scan, scans/s, and
that it runs without error)."""

from __future__ import annotations

import math
import time
import traceback
from pathlib import Path

import numpy as np

from benchmarks import perception_scoring as acc
from benchmarks.common import print_lines
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.logs.vocabulary import LANDMARK_NAMES
from datmo_cli.perception.features import RunFeatures, extract_run
from datmo_cli.perception.params import FeatureParams
from datmo_cli.report import decode_channel

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_LOGS = ROOT / "sample_logs"
SHARED = ROOT.parent / "shared" / "data"
SIMULATED = ("hall", "corridor", "crowd6", "static", "patrol")

WALL_ANGLE_DEG, WALL_RHO = 1.0, 0.02
LEG_CENTRE, LEG_RADIUS = 0.03, 0.02
COLUMN_CENTRE = 0.03
LANDMARK_RECALL, LANDMARK_SPURIOUS = 0.95, 0.05
LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan", "sensor_msgs/LaserScan")


def _stat(values: np.ndarray, q: float, scale: float = 1.0) -> float:
    return float(np.percentile(values, q)) * scale if len(values) else float("nan")


def _vs(measured: float, target: float, unit: str, at_most: bool = True) -> str:
    """'measured unit (target <= x unit: met)'."""
    unit = unit if unit in ("°", "%") else f" {unit}"
    op = "<=" if at_most else ">="
    if not np.isfinite(measured):
        return f"n/a (target {op} {target:g}{unit})"
    ok = measured <= target if at_most else measured >= target
    return f"{measured:.2f}{unit} (target {op} {target:g}{unit}: {'met' if ok else 'NOT met'})"


def simulated(name: str) -> list[str]:
    """Target vs measured on one simulated sample log."""
    log = mcapio.read_log(SAMPLE_LOGS / f"{name}.mcap", topics=None)
    run, odom = mcapio.run_from_log(log), mcapio.odometry_from_log(log)
    gt = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    truth, off, theta = gt.items["objects"], gt.offsets["objects"], gt.scalars["sensor_theta"]
    f = extract_run(run, odometry=odom)
    c = f.counts()
    ang, rho = acc.wall_errors(f, truth, off, theta)
    centre, radius, share = acc.leg_errors(f, truth, off)
    cols = acc.column_errors(f, truth, off)
    score = acc.landmark_score(f, truth, off, corner_scans=acc.corner_observed(run, truth, off, theta))
    out = [
        f"{len(run)} scans x {run.geometry.n_beams} beams; per scan {c['segments']:.1f} segments, "
        f"{c['lines']:.1f} lines, {c['circles']:.1f} circles, {c['blobs']:.1f} blobs"
    ]
    if len(ang):
        out += [
            f"walls ({len(ang)} lines >= 0.5 m on a true wall): angle median "
            f"{_vs(_stat(ang, 50), WALL_ANGLE_DEG, '°')}, p90 {_stat(ang, 90):.2f}°",
            f"  rho median {_vs(_stat(rho, 50, 100), WALL_RHO * 100, 'cm')}, p90 {_stat(rho, 90, 100):.2f} cm",
        ]
    else:
        out.append("walls: none matched")
    if len(centre):
        out += [
            f"legs within 4 m: {share:.0%} of visible legs found as circles; centre median "
            f"{_vs(_stat(centre, 50, 100), LEG_CENTRE * 100, 'cm')}",
            f"  radius median {_vs(_stat(radius, 50, 100), LEG_RADIUS * 100, 'cm')}",
        ]
    else:
        out.append("legs within 4 m: none in the scene")
    if len(cols):
        median = _vs(_stat(cols, 50, 100), COLUMN_CENTRE * 100, "cm")
        out.append(f"columns ({len(cols)} circles): centre median {median}")
    else:
        out.append("columns: none in the scene")
    found = ", ".join(f"{k} {a}/{b}" for k, (a, b) in score.found.items())
    visible = sum(b for _, b in score.found.values())
    target = " (published targets are for hall)" if name != "hall" else ""
    out += [
        f"landmarks found/visible: {found}",
        f"  recall {_vs(100 * score.recall, 100 * LANDMARK_RECALL, '%', at_most=False) if visible else 'n/a'}{target}",
        f"  spurious {score.spurious}/{score.defined} defined landmarks = "
        f"{_vs(100 * score.spurious_share, 100 * LANDMARK_SPURIOUS, '%')}; undefined line ends "
        f"{score.line_ends} ({score.line_ends_on_corners} on a true corner)",
    ]
    return out


# --- synthetic scans ---------------------------------------------------------------------------------------

GEOMETRY = ScanGeometry(-math.pi / 2, math.radians(0.5), 361, 0.0, 8.0, 0.0, 0.2, "laser")
LEG = (2.0, math.radians(-30), 0.10)  # range of the centre, bearing, radius
COLUMN = (3.0, math.radians(35), 0.20)
WALLS = ((3.5, 0.0), (4.0, 25.0), (5.0, -40.0), (4.5, 70.0))  # distance (m), normal angle (deg)
N_SYNTH = 200


def _wall(rho: float, theta: float, a: np.ndarray) -> np.ndarray:
    c = np.cos(a - theta)
    return np.where(c > 1e-9, rho / np.maximum(c, 1e-9), np.inf)


def _circle(rng_c: float, bearing: float, r: float, a: np.ndarray) -> np.ndarray:
    cx, cy = rng_c * math.cos(bearing), rng_c * math.sin(bearing)
    b = np.cos(a) * cx + np.sin(a) * cy
    disc = b * b - (cx * cx + cy * cy - r * r)
    return np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)


def synthetic_run(rho: float, theta_deg: float, seed: int = 0) -> ScanRun:
    """N_SYNTH scans of a wall (distance rho, normal angle theta) behind a leg and a column, σ = 1 cm."""
    a = GEOMETRY.angles()
    clean = np.minimum.reduce([_wall(rho, math.radians(theta_deg), a), _circle(*LEG, a), _circle(*COLUMN, a)])
    noisy = clean[None, :] + np.random.default_rng(seed).normal(0.0, 0.01, (N_SYNTH, len(a)))
    noisy[~np.isfinite(noisy) | (noisy > GEOMETRY.range_max - 0.05)] = np.inf
    return ScanRun(np.arange(N_SYNTH, dtype=np.int64) * 200_000_000, noisy.astype(np.float32), GEOMETRY)


def wall_line_errors(f: RunFeatures, rho: float, theta: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(angle errors deg, rho errors m, scans with a wall line) of the lines longer than 1 m."""
    lines = f.lines[f.lines["length"] > 1.0]
    d = lines["theta"].astype(np.float64) - theta
    ang = np.degrees(np.abs((d + np.pi / 2) % np.pi - np.pi / 2))
    signed = np.where(np.cos(d) >= 0, lines["rho"], -lines["rho"])
    scans = len(np.unique(np.searchsorted(f.line_offsets, np.flatnonzero(f.lines["length"] > 1.0), "right")))
    return ang, np.abs(signed - rho), scans


def circle_errors(f: RunFeatures, obj: tuple[float, float, float], match: float = 0.15):
    """(centre errors m, radius errors m, scans with a circle within `match` of the true centre)."""
    cx, cy = obj[0] * math.cos(obj[1]), obj[0] * math.sin(obj[1])
    d = np.hypot(f.circles["x"] - cx, f.circles["y"] - cy)
    near = np.flatnonzero(d <= match)
    scans = np.searchsorted(f.circle_offsets, near, "right") - 1
    best = {}
    for i, k in zip(near.tolist(), scans.tolist(), strict=True):
        if k not in best or d[i] < d[best[k]]:
            best[k] = i
    idx = np.array(sorted(best.values()), np.int64)
    return d[idx], np.abs(f.circles["radius"][idx] - obj[2]), len(idx)


def synthetic() -> list[str]:
    out = [
        f"{N_SYNTH} scans each, 361 beams over 180°, σ = 1 cm; leg r = {LEG[2] * 100:.0f} cm at "
        f"{LEG[0]:.0f} m, column r = {COLUMN[2] * 100:.0f} cm at {COLUMN[0]:.0f} m, in front of the wall"
    ]
    for k, (rho, th) in enumerate(WALLS):
        f = extract_run(synthetic_run(rho, th, seed=k))
        ang, drho, wall_scans = wall_line_errors(f, rho, math.radians(th))
        lc, lr, leg_scans = circle_errors(f, LEG)
        cc, cr, col_scans = circle_errors(f, COLUMN)
        db = f.landmarks.final()
        kinds = ", ".join(f"{int((db['type'] == t).sum())} {LANDMARK_NAMES[t]}" for t in np.unique(db["type"]).tolist())
        out += [
            f"wall at {rho} m, normal {th:+.0f}°: in {wall_scans}/{N_SYNTH} scans; angle median "
            f"{_vs(_stat(ang, 50), WALL_ANGLE_DEG, '°')}, rho median {_vs(_stat(drho, 50, 100), 2, 'cm')}",
            f"  leg at {LEG[0]} m: in {leg_scans}/{N_SYNTH} scans; centre median "
            f"{_vs(_stat(lc, 50, 100), LEG_CENTRE * 100, 'cm')}, radius median "
            f"{_vs(_stat(lr, 50, 100), LEG_RADIUS * 100, 'cm')}",
            f"  column at {COLUMN[0]} m: in {col_scans}/{N_SYNTH} scans; centre median "
            f"{_vs(_stat(cc, 50, 100), COLUMN_CENTRE * 100, 'cm')}, radius median {_stat(cr, 50, 100):.2f} cm",
            f"  landmarks: {kinds or 'none'}",
        ]
    return out


# --- real data ---------------------------------------------------------------------------------------------


def scan_topics(bag: Path) -> list[str]:
    """Every sensor_msgs/LaserScan topic of a ROS bag."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return sorted({c.topic for c in reader.connections if c.msgtype in LASERSCAN_TYPES})


def real_logs() -> list[tuple[Path, str | None]]:
    """(path, topic) of every real log in ../shared/data: CARMEN logs, Killian, each legtracker bag topic."""
    out: list[tuple[Path, str | None]] = [(p, None) for p in sorted((SHARED / "carmen").glob("*.log.gz"))]
    out += [(p, None) for p in sorted((SHARED / "killian").glob("*.g2o.gz"))]
    for bag in sorted((SHARED / "legtracker").glob("*.bag")):
        out += [(bag, t) for t in scan_topics(bag)]
    return out


def real(path: Path, topic: str | None) -> str:
    from datmo_cli.logs.importers import import_log

    imported = import_log(path, topic)
    run = imported.run
    t0 = time.perf_counter()
    f = extract_run(run, odometry=imported.odometry)
    dt = time.perf_counter() - t0
    c = f.counts()
    db = f.landmarks.final()
    per_scan = np.diff(f.landmarks.snap_offsets).mean() if len(run) else 0.0
    kinds = ", ".join(f"{int((db['type'] == t).sum())} {LANDMARK_NAMES[t]}" for t in np.unique(db["type"]).tolist())
    g = run.geometry
    return (
        f"ok: {len(run)} scans x {g.n_beams} beams ({math.degrees(g.angle_increment):.2f}°), "
        f"{len(run) / dt:,.0f} scans/s; per scan {c['lines']:.1f} lines, {c['circles']:.1f} circles, "
        f"{c['blobs']:.1f} blobs, {per_scan:.1f} landmarks in the database; at the end {len(db)} "
        f"({kinds or 'none'}) in the {f.landmark_frame} frame"
    )


# the circle rule before the well-posedness tests: all four off
BEFORE_CIRCLES = {
    "circle_min_coverage": 0,
    "circle_residual_ratio": 0,
    "circle_radius_margin": 0,
    "circle_lines_ratio": 0,
}
BOUND = 0.005  # m; a radius within this of circle_radius_min or circle_radius_max (or beyond) is at a bound


def circle_figures(f: RunFeatures, p: FeatureParams) -> str:
    """Circles per scan, the most in one scan, the share at a radius bound and the share of 3-point circles."""
    c = f.circles
    per = np.diff(f.circle_offsets)
    if not len(c):
        return "0.00/scan"
    bound = (c["radius"] <= p.circle_radius_min + BOUND) | (c["radius"] >= p.circle_radius_max - BOUND)
    return (
        f"{len(c) / max(len(f), 1):.2f}/scan, max {int(per.max())}, {np.mean(bound):.0%} at a radius bound, "
        f"{np.mean(c['n_points'] == 3):.0%} of 3 points"
    )


def carmen_circles() -> list[str]:
    """Circles on the CARMEN office logs before (the old rule: the well-posedness tests off) and after."""
    from datmo_cli.logs.importers import import_log

    before, after = FeatureParams().replace(**BEFORE_CIRCLES), FeatureParams()
    out = [
        f"before: {', '.join(f'{k} 0' for k in BEFORE_CIRCLES)}; after: the defaults "
        f"({', '.join(f'{k} {getattr(after, k):g}' for k in BEFORE_CIRCLES)}); at a bound: radius within "
        f"{BOUND * 100:g} cm of circle_radius_min/max"
    ]
    for path in sorted((SHARED / "carmen").glob("*.log.gz")):
        run = import_log(path, None).run
        b, a = (circle_figures(extract_run(run, p, landmarks=False), p) for p in (before, after))
        out.append(f"{path.name.removesuffix('-corrected.log.gz')}: before {b}; after {a}")
    return out


def main() -> None:
    for name in SIMULATED:
        print_lines(f"Perception against ground truth: {name}", simulated(name))
    print_lines("Perception on synthetic scans", synthetic())
    if not SHARED.is_dir():
        print_lines("Perception on real logs", [f"{SHARED} is absent: real-data figures skipped"])
        return
    extract_run(synthetic_run(4.0, 0.0).slice(0, 5))  # warm-up before timing
    lines, failed = [], 0
    for path, topic in real_logs():
        label = f"{path.parent.name}/{path.name}{' ' + topic if topic else ''}"
        try:
            lines.append(f"{label}: {real(path, topic)}")
        except Exception as exc:  # report every log, whatever fails
            failed += 1
            last = traceback.extract_tb(exc.__traceback__)[-1]
            lines.append(f"{label}: FAILED: {type(exc).__name__}: {exc} ({last.filename}:{last.lineno})")
    lines.append(f"{len(lines) - failed} of {len(lines)} logs ran without error")
    print_lines(f"Perception on real logs ({SHARED})", lines)
    print_lines("Circles on the CARMEN logs, before and after the well-posed arc rule", carmen_circles())


if __name__ == "__main__":
    main()
