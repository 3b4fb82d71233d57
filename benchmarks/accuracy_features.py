"""Feature and landmark accuracy (make accuracy): the simulated sample logs against their ground truth,
synthetic scans of known geometry, and every real log in ../shared/data (lines, circles and landmarks per
scan, and that it runs)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from benchmarks.common import print_lines
from datmo_cli.log import mcapio, types
from datmo_cli.log.scan import ScanGeometry, ScanRun
from datmo_cli.perception import accuracy as acc
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.landmarks import TYPE_NAMES
from datmo_cli.report import decode_channel

ROOT = Path(__file__).resolve().parent.parent
LOGS = ROOT / "sample_logs"
SHARED = ROOT.parent / "shared" / "data"
SIMULATED = ("hall", "corridor", "crowd6", "static", "patrol")


def median(values: np.ndarray, scale: float = 1.0) -> str:
    return f"{np.median(values) * scale:.2f}" if len(values) else "n/a"


def p90(values: np.ndarray, scale: float = 1.0) -> str:
    return f"{np.percentile(values, 90) * scale:.2f}" if len(values) else "n/a"


def simulated(name: str) -> list[str]:
    log = mcapio.read_log(LOGS / f"{name}.mcap", topics=None)
    run, odom = mcapio.run_from_log(log), mcapio.odometry_from_log(log)
    gt = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    truth, off, theta = gt.items["objects"], gt.offsets["objects"], gt.scalars["sensor_theta"]
    f = extract_run(run, odometry=odom)
    ang, dist = acc.wall_errors(f, truth, off, theta)
    centre, radius, share = acc.leg_errors(f, truth, off)
    cols = acc.column_errors(f, truth, off)
    score = acc.landmark_score(f, truth, off, corner_scans=acc.corner_observed(run, truth, off, theta))
    found = ", ".join(f"{k} {a}/{b}" for k, (a, b) in score.found.items())
    c = f.counts()
    return [
        f"{name}: per scan {c['lines']:.1f} lines, {c['circles']:.1f} circles, {c['blobs']:.1f} blobs",
        f"  walls ({len(ang)} lines): angle median {median(ang)}° p90 {p90(ang)}° (target 1°); "
        f"distance median {median(dist, 100)} cm p90 {p90(dist, 100)} cm (target 2 cm)",
        f"  legs within 4 m: {share:.0%} found as circles; centre median {median(centre, 100)} cm (target 3 cm), "
        f"radius median {median(radius, 100)} cm (target 2 cm)",
        f"  columns ({len(cols)} circles): centre median {median(cols, 100)} cm (target 3 cm)",
        f"  landmarks found/observable: {found}; recall {score.recall:.0%} (target 95%); "
        f"spurious {score.spurious}/{score.defined} = {score.spurious_share:.0%} (target <= 5%); "
        f"undefined line ends {score.line_ends} ({score.line_ends_on_corners} on a corner)",
    ]


def synthetic() -> list[str]:
    """A wall at 3 m and 70°, a leg at 2 m and a column at 3 m in front of a wall, σ = 1 cm, 200 scans."""
    rng = np.random.default_rng(0)
    g = ScanGeometry(-math.pi / 2, math.radians(0.5), 361, 0.0, 8.0, 0.0, 0.2, "laser")
    a = g.angles()

    def wall(rho: float, theta: float) -> np.ndarray:
        c = np.cos(a - theta)
        return np.where(c > 1e-9, rho / np.maximum(c, 1e-9), np.inf)

    def circle(cx: float, cy: float, r: float) -> np.ndarray:
        b = np.cos(a) * cx + np.sin(a) * cy
        disc = b * b - (cx * cx + cy * cy - r * r)
        return np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)

    clean = np.minimum.reduce([wall(3.0, math.radians(70)), circle(2.0, -0.8, 0.1), circle(2.5, -2.0, 0.25)])
    clean[clean > 7.9] = np.inf
    ranges = (clean[None, :] + rng.normal(0, 0.01, (200, 361))).astype(np.float32)
    run = ScanRun(np.arange(200, dtype=np.int64) * 200_000_000, ranges, g)
    f = extract_run(run, landmarks=False)
    lines = f.lines[f.lines["length"] > 1.0]
    ang = np.degrees(np.abs((lines["theta"] - math.radians(70) + np.pi / 2) % np.pi - np.pi / 2))
    dist = np.abs(lines["rho"] - 3.0)
    out = [f"synthetic (200 scans, σ = 1 cm): wall angle median {median(ang)}°, distance median {median(dist, 100)} cm"]
    for name, (cx, cy, r) in (("leg at 2.2 m", (2.0, -0.8, 0.1)), ("column at 3.2 m", (2.5, -2.0, 0.25))):
        d = np.hypot(f.circles["x"] - cx, f.circles["y"] - cy)
        near = f.circles[d < 0.15]
        out.append(f"  {name}: found in {len(near)}/200 scans; centre median {median(d[d < 0.15], 100)} cm, radius "
                   f"median error {median(np.abs(near['radius'] - r), 100)} cm")
    return out


def real_logs() -> list[tuple[str, Path, str | None]]:
    """(label, path, topic) of every real log in ../shared/data."""
    out = [(p.name, p, None) for p in sorted((SHARED / "carmen").glob("*.log.gz"))]
    out.append(("killian.g2o.gz", SHARED / "killian" / "killian.g2o.gz", None))
    for bag in sorted((SHARED / "legtracker").glob("*.bag")):
        topics = ("/left_scan", "/right_scan", "/rear_scan") if bag.name.startswith("negative") else (None,)
        out.extend((f"{bag.name}{' ' + t if t else ''}", bag, t) for t in topics)
    return out


def real(label: str, path: Path, topic: str | None) -> str:
    from datmo_cli.log.importers import import_log

    imported = import_log(path, topic)
    run = imported.run
    t0 = time.perf_counter()
    f = extract_run(run, odometry=imported.odometry)
    dt = time.perf_counter() - t0
    c = f.counts()
    db = f.landmarks.final()
    kinds = ", ".join(f"{int((db['type'] == k).sum())} {TYPE_NAMES[k]}" for k in range(len(TYPE_NAMES))
                      if (db["type"] == k).any())
    return (f"{label}: {len(run)} scans x {run.geometry.n_beams} beams, {len(run) / dt:,.0f} scans/s; per scan "
            f"{c['lines']:.1f} lines, {c['circles']:.1f} circles, {c['blobs']:.1f} blobs; "
            f"{len(db)} landmarks ({kinds or 'none'})")


def main() -> None:
    for name in SIMULATED:
        print_lines(f"Features against ground truth: {name}", simulated(name))
    print_lines("Features of synthetic scans", synthetic())
    if not SHARED.is_dir():
        print_lines("Real data", [f"{SHARED} is absent: real-data figures skipped"])
        return
    lines = []
    for label, path, topic in real_logs():
        try:
            lines.append(real(label, path, topic))
        except Exception as exc:  # noqa: BLE001 - report every log, whatever fails
            lines.append(f"{label}: FAILED: {type(exc).__name__}: {exc}")
    print_lines("Features of real logs (../shared/data)", lines)


if __name__ == "__main__":
    main()
