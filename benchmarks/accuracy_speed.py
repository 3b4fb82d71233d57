"""Speeds of people against ground truth (make accuracy): the simulated scenes run as `datmo run` runs them, with
hindsight (the default track.hindsight_lag) and without (lag 0: the causal tracker, as `datmo node` and `datmo play`
give it), and the velocity of the confirmed person tracks scored against the simulator's.

Velocities are compared in the sensor's axes (m/s): a track's (vx, vy) is its ground velocity turned into the
sensor frame (tracking.hindsight, tracker.write_tracks), and the truth's the same, R(-sensor_theta) (world_vx,
world_vy). Matching as benchmarks.accuracy_scenes (confirmed tracks to visible people within 0.5 m, one to one).

Figures per scene: the velocity RMS error of confirmed person tracks matched to a person (m/s) and its median; the
fastest confirmed person track (m/s) beside the fastest simulated walker. Targets (the hall, the paper's scene
simulated for HALL_SECONDS s): RMS error <= 0.20 m/s and no person faster than 1.5x the fastest walker.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from benchmarks import accuracy_scenes as sc
from benchmarks.common import print_lines
from datmo_cli.logs.vocabulary import CLASS_PERSON, STATUS_CONFIRMED

HALL_SECONDS = 3600.0  # the hall at 5 Hz for the simulator's longest run: 18,000 scans, people looping on their paths
SCENES = (("hall", HALL_SECONDS), ("following", None), ("lab-drive", None))
RMS_TARGET = 0.20  # m/s, the hall
FASTEST_RATIO = 1.5  # no person faster than this times the fastest walker


def truth_velocity(run: sc.SceneRun) -> np.ndarray:
    """(M, 2) the ground truth's ground velocity in the sensor's axes, m/s, one row per run.gt row."""
    theta = np.zeros(run.frames) if run.sensor_theta is None else np.asarray(run.sensor_theta, np.float64)
    th = np.repeat(theta, np.diff(run.gt_offsets))
    c, s = np.cos(th), np.sin(th)
    vx, vy = run.gt["world_vx"].astype(np.float64), run.gt["world_vy"].astype(np.float64)
    return np.stack([c * vx + s * vy, -s * vx + c * vy], axis=1)


def speed_figures(run: sc.SceneRun) -> dict:
    """{"rms", "median" (m/s: velocity error of confirmed person tracks matched to a person), "rows" (matched
    rows), "max_person" (m/s: the fastest confirmed person track), "fastest_walker" (m/s: the fastest person of
    the truth)}; None where there is nothing to measure."""
    matched = sc.match(run, lambda g: g["classification"] == CLASS_PERSON)
    t = run.tracks
    person = (t["status"] == STATUS_CONFIRMED) & (t["classification"] == CLASS_PERSON)
    rows = np.flatnonzero(matched >= 0)
    rows = rows[person[matched[rows]]]
    truth = truth_velocity(run)[rows]
    tr = matched[rows]
    err = np.hypot(t["vx"][tr].astype(np.float64) - truth[:, 0], t["vy"][tr].astype(np.float64) - truth[:, 1])
    speeds = np.hypot(t["vx"][person].astype(np.float64), t["vy"][person].astype(np.float64))
    walkers = run.gt["classification"] == CLASS_PERSON
    gt_speed = np.hypot(run.gt["world_vx"][walkers].astype(np.float64), run.gt["world_vy"][walkers])
    return {
        "rms": float(np.sqrt(np.mean(err**2))) if len(err) else None,
        "median": float(np.median(err)) if len(err) else None,
        "rows": len(err),
        "max_person": float(speeds.max()) if len(speeds) else None,
        "fastest_walker": float(gt_speed.max()) if len(gt_speed) else None,
    }


def scene_speeds(scene: str, folder: Path, duration: float | None = None, lags=(None, 0.0)) -> dict:
    """{lag: speed_figures} of `scene` simulated once and run with each hindsight lag (None: the default)."""
    from datmo_cli.passes.config import DatmoConfig

    folder = Path(folder)
    log = sc.simulate(scene, folder / f"{scene}.mcap", duration=duration)
    out = {}
    for lag in lags:
        config = DatmoConfig() if lag is None else DatmoConfig().replace(track={"hindsight_lag": lag})
        tracked = sc.process(log, folder / f"{scene}-lag{lag}.mcap", config)
        out[lag] = speed_figures(sc.load(log, tracked))
    return out


def _f(v) -> str:
    return "n/a" if v is None else f"{v:.3f}"


def lines(folder: Path) -> list[str]:
    from datmo_cli.tracking.params import TrackingParams

    default = TrackingParams().hindsight_lag
    out = []
    for scene, duration in SCENES:
        figures = scene_speeds(scene, folder, duration)
        for lag, f in figures.items():
            name = f"hindsight {default:g} s" if lag is None else "causal (no hindsight)"
            verdict = ""
            if scene == "hall" and f["rms"] is not None and f["max_person"] is not None:
                ok = f["rms"] <= RMS_TARGET and f["max_person"] <= FASTEST_RATIO * f["fastest_walker"]
                verdict = "   meets" if ok else "   MISSES"
            out.append(
                f"{scene:10s} {name:22s} person velocity RMS error {_f(f['rms'])} m/s (median {_f(f['median'])}, "
                f"{f['rows']} matched rows); fastest person {_f(f['max_person'])} m/s, fastest walker "
                f"{_f(f['fastest_walker'])}{verdict}"
            )
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        print_lines(
            f"Person speeds against ground truth (target on the hall: RMS error <= {RMS_TARGET} m/s, no person "
            f"faster than {FASTEST_RATIO}x the fastest walker)",
            lines(Path(tmp)),
        )


if __name__ == "__main__":
    main()
