"""Feature and landmark accuracy against the simulator's ground truth (for `make accuracy` and the tests).

Ground truth is the flat GroundTruthObject array of a run with per-scan offsets; positions in the sensor
frame unless named world_*. Errors in metres and degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datmo_cli.logs.vocabulary import (
    CLASS_BENCH,
    CLASS_COLUMN,
    CLASS_PERSON,
    CLASS_WALL,
    CLASS_WALL_CORNER,
    LANDMARK_BENCH,
    LANDMARK_COLUMN,
    LANDMARK_CONCAVE_DEFLECTION,
    LANDMARK_CONVEX_DEFLECTION,
    LANDMARK_CORNER,
    LANDMARK_LINE_END,
)
from datmo_cli.perception.features import RunFeatures

LEG_RADIUS = 0.10


def _per_scan(offsets: np.ndarray) -> np.ndarray:
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))


def wall_errors(
    f: RunFeatures, truth: np.ndarray, truth_offsets: np.ndarray, sensor_theta: np.ndarray, min_length: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """(angle errors in degrees, rho errors in m) of every line at least `min_length` long that lies on a
    ground-truth wall (normal within 5 degrees and 10 cm, midpoint within the wall's extent)."""
    ang, dist = [], []
    for k in range(len(f)):
        walls = truth[truth_offsets[k] : truth_offsets[k + 1]]
        walls = walls[walls["classification"] == CLASS_WALL]
        lines = f.lines[f.line_offsets[k] : f.line_offsets[k + 1]]
        lines = lines[lines["length"] >= min_length]
        if not len(walls) or not len(lines):
            continue
        direction = walls["orientation"].astype(np.float64) - sensor_theta[k]
        th = (direction + np.pi / 2) % np.pi
        rho = walls["x"] * np.cos(th) + walls["y"] * np.sin(th)
        for ln in lines:
            dth = (ln["theta"] - th + np.pi / 2) % np.pi - np.pi / 2
            drho = np.where(np.abs(ln["theta"] - th) < np.pi / 2, ln["rho"] - rho, ln["rho"] + rho)
            # equal normal angles near 0 and pi flip the sign of rho
            flip = np.abs(ln["theta"] - th) > np.pi / 2
            drho = np.where(flip, ln["rho"] + rho, ln["rho"] - rho)
            mx, my = 0.5 * (ln["x_ini"] + ln["x_end"]), 0.5 * (ln["y_ini"] + ln["y_end"])
            along = np.abs((mx - walls["x"]) * np.cos(direction) + (my - walls["y"]) * np.sin(direction))
            ok = (np.abs(dth) < np.radians(5)) & (np.abs(drho) < 0.1) & (along <= walls["length"] / 2 + 0.1)
            if ok.any():
                j = np.flatnonzero(ok)[np.argmin(np.abs(drho[ok]))]
                ang.append(np.degrees(abs(dth[j])))
                dist.append(abs(drho[j]))
    return np.array(ang), np.array(dist)


def leg_errors(
    f: RunFeatures, truth: np.ndarray, truth_offsets: np.ndarray, max_range: float = 4.0, match: float = 0.15
) -> tuple[np.ndarray, np.ndarray, float]:
    """(centre errors m, radius errors m, share of visible legs within max_range that got a circle) of the
    circles within `match` of a true leg centre (radius 10 cm)."""
    centre, radius = [], []
    legs_seen = legs_found = 0
    for k in range(len(f)):
        objs = truth[truth_offsets[k] : truth_offsets[k + 1]]
        people = objs[(objs["classification"] == CLASS_PERSON) & (objs["visible"] == 1)]
        if not len(people):
            continue
        legs = np.concatenate(
            [
                np.stack([people["left_leg_x"], people["left_leg_y"]], 1),
                np.stack([people["right_leg_x"], people["right_leg_y"]], 1),
            ]
        ).astype(np.float64)
        legs = legs[np.hypot(legs[:, 0], legs[:, 1]) <= max_range]
        circles = f.circles[f.circle_offsets[k] : f.circle_offsets[k + 1]]
        legs_seen += len(legs)
        if not len(circles) or not len(legs):
            continue
        d = np.hypot(circles["x"][:, None] - legs[None, :, 0], circles["y"][:, None] - legs[None, :, 1])
        for j in range(len(legs)):
            i = int(np.argmin(d[:, j]))
            if d[i, j] <= match:
                legs_found += 1
                centre.append(d[i, j])
                radius.append(abs(float(circles["radius"][i]) - LEG_RADIUS))
    return np.array(centre), np.array(radius), legs_found / max(legs_seen, 1)


def column_errors(f: RunFeatures, truth: np.ndarray, truth_offsets: np.ndarray, match: float = 0.3) -> np.ndarray:
    """Centre errors (m) of the circles within `match` of a true column."""
    out = []
    for k in range(len(f)):
        objs = truth[truth_offsets[k] : truth_offsets[k + 1]]
        cols = objs[(objs["classification"] == CLASS_COLUMN) & (objs["visible"] == 1)]
        circles = f.circles[f.circle_offsets[k] : f.circle_offsets[k + 1]]
        if not len(cols) or not len(circles):
            continue
        d = np.hypot(circles["x"][:, None] - cols["x"][None, :], circles["y"][:, None] - cols["y"][None, :])
        best = d.min(axis=0)
        out.extend(best[best <= match].tolist())
    return np.array(out)


@dataclass
class LandmarkScore:
    """Landmark database against the true static landmarks (columns, benches, wall corners)."""

    found: dict[str, tuple[int, int]]  # class -> (found, visible)
    spurious: int  # defined landmarks (not line ends) near no true landmark
    defined: int  # defined landmarks in the database
    line_ends: int
    line_ends_on_corners: int

    @property
    def recall(self) -> float:
        f = sum(a for a, _ in self.found.values())
        n = sum(b for _, b in self.found.values())
        return f / n if n else 1.0

    @property
    def spurious_share(self) -> float:
        return self.spurious / self.defined if self.defined else 0.0


def corner_observed(
    run,
    truth: np.ndarray,
    truth_offsets: np.ndarray,
    sensor_theta: np.ndarray,
    reach: float = 0.5,
    near: float = 0.03,
    min_points: int = 4,
    c0: float = 0.08,
) -> dict[int, int]:
    """For each true wall corner id, the number of scans in which the method can see it as a corner: each of
    its two walls has at least `min_points` scan points (the paper keeps a line of more than 3 points) within
    `near` of the wall line, within `reach` of the vertex and not on the other wall, and these points with
    the vertex's are one segment's worth: no gap between successive points is wider than the segmentation
    threshold c0 + c1 * r (a wall seen at a grazing angle, its returns farther apart than that, breaks into
    single points, which no line can be made of). Sensor frame."""
    angles = run.geometry.angles()
    c1 = float(np.sqrt(2.0 * (1.0 - np.cos(run.geometry.angle_increment))))
    out: dict[int, int] = {}
    for k in range(len(run)):
        objs = truth[truth_offsets[k] : truth_offsets[k + 1]]
        corners = objs[objs["classification"] == CLASS_WALL_CORNER]
        walls = objs[objs["classification"] == CLASS_WALL]
        if not len(corners):
            continue
        r = run.ranges[k].astype(np.float64)
        ok = np.isfinite(r)
        pr = r[ok]
        px, py = (r * np.cos(angles))[ok], (r * np.sin(angles))[ok]
        d = walls["orientation"].astype(np.float64) - sensor_theta[k]
        ux, uy = np.cos(d), np.sin(d)
        h = walls["length"] / 2
        ends = np.stack([walls["x"] - ux * h, walls["y"] - uy * h, walls["x"] + ux * h, walls["y"] + uy * h], 1)
        for c in corners:
            cx, cy = float(c["x"]), float(c["y"])
            touching = np.flatnonzero(
                (np.hypot(ends[:, 0] - cx, ends[:, 1] - cy) < 0.02)
                | (np.hypot(ends[:, 2] - cx, ends[:, 3] - cy) < 0.02)
            )[:2]
            if len(touching) < 2:
                continue
            close = np.hypot(px - cx, py - cy) <= reach
            on = [close & (np.abs(-(px - cx) * uy[w] + (py - cy) * ux[w]) <= near) for w in touching.tolist()]
            sides = [on[0] & ~on[1], on[1] & ~on[0]]
            if min(int(np.count_nonzero(side)) for side in sides) < min_points:
                continue
            chain = np.flatnonzero(on[0] | on[1])  # in beam order: both walls and the vertex's points
            gap = np.hypot(np.diff(px[chain]), np.diff(py[chain]))
            if np.all(gap <= c0 + c1 * np.minimum(pr[chain][:-1], pr[chain][1:])):
                out[int(c["id"])] = out.get(int(c["id"]), 0) + 1
    return out


def landmark_score(
    f: RunFeatures,
    truth: np.ndarray,
    truth_offsets: np.ndarray,
    match: float = 0.2,
    min_scans: int = 10,
    corner_scans: dict[int, int] | None = None,
) -> LandmarkScore:
    """Score the database after the last scan. A column or bench counts when hit by at least 3 beams in at
    least `min_scans` scans; a wall corner when it can be seen as a corner (both walls, see corner_observed)
    in at least `min_scans` scans. It is found when a landmark of a fitting type lies within `match` (a wall
    corner may be found as a corner, a deflection or a line end). Positions compared in the database's
    frame (world with odometry, else the sensor frame)."""
    db = f.landmarks.final()
    world = f.landmark_frame != f.frame_id
    kx, ky = ("world_x", "world_y") if world else ("x", "y")
    wanted = {CLASS_COLUMN: "column", CLASS_BENCH: "bench", CLASS_WALL_CORNER: "wall_corner"}
    scans = _per_scan(truth_offsets)
    found: dict[str, tuple[int, int]] = {}
    true_xy = []
    for cls, name in wanted.items():
        sel = truth["classification"] == cls
        ids = np.unique(truth["id"][sel])
        nf = nv = 0
        for i in ids.tolist():
            rows = truth[sel & (truth["id"] == i)]
            true_xy.append((float(rows[kx][-1]), float(rows[ky][-1])))
            seen = len(np.unique(scans[np.flatnonzero(sel & (truth["id"] == i))][rows["n_beams"] >= 3]))
            if cls == CLASS_WALL_CORNER and corner_scans is not None:
                seen = corner_scans.get(i, 0)
            if seen < min_scans:
                continue
            nv += 1
            x, y = float(rows[kx][-1]), float(rows[ky][-1])
            types = {CLASS_COLUMN: (LANDMARK_COLUMN,), CLASS_BENCH: (LANDMARK_BENCH,)}.get(
                cls, (LANDMARK_CORNER, LANDMARK_CONVEX_DEFLECTION, LANDMARK_CONCAVE_DEFLECTION, LANDMARK_LINE_END)
            )
            near = np.isin(db["type"], types) & (np.hypot(db["x"] - x, db["y"] - y) <= match)
            nf += bool(near.any())
        found[name] = (nf, nv)
    txy = np.array(true_xy).reshape(-1, 2)
    defined = db[db["type"] != LANDMARK_LINE_END]
    ends = db[db["type"] == LANDMARK_LINE_END]

    def near_truth(items: np.ndarray) -> np.ndarray:
        if not len(txy) or not len(items):
            return np.zeros(len(items), bool)
        return (np.hypot(items["x"][:, None] - txy[None, :, 0], items["y"][:, None] - txy[None, :, 1]) <= match).any(
            axis=1
        )

    return LandmarkScore(found, int((~near_truth(defined)).sum()), len(defined), len(ends), int(near_truth(ends).sum()))
