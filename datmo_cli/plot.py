"""The run seen from above, like Fig. 7c of Castro, Nunes and Ruano (2004): faded scan points, landmarks,
trajectories of confirmed tracks coloured by class with their ids, and the scanner's pose.

Everything is drawn in the world (odometry) frame when the log has odometry and world-frame tracks,
else in the sensor frame. Metres. matplotlib is imported here only, with the Agg canvas (no display).
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np

from .report import CLASS_NAMES, LANDMARK_NAMES, STATUS_CONFIRMED, RunData, track_history

CLASS_COLOURS = {0: "tab:gray", 1: "tab:red", 2: "tab:blue", 3: "tab:green"}
LANDMARK_MARKERS = {0: "v", 1: "^", 2: "<", 3: "x", 4: "o", 5: "s"}
FORMATS = (".png", ".svg", ".pdf")


def _scan_points(data: RunData, world: bool, max_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Valid scan points (x, y) of a subsample of scans, and the sensor poses (K x 3) in the drawing frame."""
    run = data.scans
    if run is None:
        return np.zeros(0), np.zeros(0), None
    n = len(run)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(run.ranges) & (run.ranges > run.geometry.range_min) & (run.ranges < run.geometry.range_max)
    per_scan = max(1, int(valid.sum() / max(n, 1)))
    step = max(1, int(np.ceil(n * per_scan / max_points)))
    idx = np.arange(0, n, step)
    a = run.geometry.angles()
    keep = valid[idx]
    r = np.where(keep, run.ranges[idx], 0.0).astype(np.float64)  # no inf * 0 at the ±90° beams
    x, y = r * np.cos(a), r * np.sin(a)
    poses = None
    if world and data.odometry is not None:
        poses = data.odometry.at(run.stamps[idx])
        c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
        x, y = poses[:, 0:1] + c * x - s * y, poses[:, 1:2] + s * x + c * y
    return x[keep], y[keep], poses


def _sensor_marker(ax, x: float, y: float, theta: float, size: float) -> None:  # noqa: ANN001
    from matplotlib.patches import Polygon

    tri = np.array([[1.0, 0.0], [-0.6, 0.55], [-0.6, -0.55]]) * size
    c, s = np.cos(theta), np.sin(theta)
    pts = tri @ np.array([[c, s], [-s, c]]) + [x, y]
    ax.add_patch(Polygon(pts, closed=True, facecolor="black", edgecolor="black", zorder=6, label="scanner"))


def plot_run(data: RunData, out: str | Path | BinaryIO, *, title: str | None = None, max_points: int = 150_000,
             dpi: int = 150) -> Path:
    """Draw `data` (a RunData with scans kept) into `out` (.png, .svg or .pdf; or an open file, in the format
    rcParams["savefig.format"] says) and return it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    out = out if hasattr(out, "write") else Path(out)
    # Scan points can be put in the world frame only with odometry; tracks follow the scan points' frame.
    hist = track_history(data.tracks, world=data.odometry is not None)
    world = hist.world
    fig = Figure(figsize=(11, 8), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    px, py, poses = _scan_points(data, world, max_points)
    ax.scatter(px, py, s=0.6, c="0.55", alpha=0.15, linewidths=0, rasterized=True, zorder=1)

    handles = [Line2D([], [], marker=".", ls="", color="0.55", label="scan points")]
    if data.landmarks is not None and len(data.landmarks) and "landmarks" in data.landmarks.items:
        off = data.landmarks.offsets["landmarks"]
        db = data.landmarks.items["landmarks"][off[-2]:off[-1]]
        for typ in sorted(set(db["type"].tolist())):
            sel = db[db["type"] == typ]
            m = LANDMARK_MARKERS.get(typ, "*")
            hollow = m in "os^v<D"
            style = {"facecolors": "none", "edgecolors": "black"} if hollow else {"c": "black"}
            ax.scatter(sel["x"], sel["y"], marker=m, s=70, linewidths=1.3, zorder=4, **style)
            handles.append(Line2D([], [], marker=m, ls="", mfc="none", mec="black",
                                  label=LANDMARK_NAMES.get(typ, str(typ))))

    classes_drawn = set()
    s = hist.states
    for g, tid in enumerate(hist.ids.tolist()):
        a, b = hist.starts[g], hist.starts[g + 1]
        st = s[a:b]
        if not (st["status"] == STATUS_CONFIRMED).any():
            continue
        cls = int(st["classification"][-1])
        colour = CLASS_COLOURS.get(cls, "tab:gray")
        classes_drawn.add(cls)
        # confirmed states only, the line broken where the track coasted (predictions, not observations)
        conf = st["status"] == STATUS_CONFIRMED
        x, y = np.where(conf, hist.x[a:b], np.nan), np.where(conf, hist.y[a:b], np.nan)
        first, last = np.flatnonzero(conf)[[0, -1]]
        x, y = x[first:last + 1], y[first:last + 1]
        if int(st["mobility"][-1]) == 0:
            ax.plot(x[-1], y[-1], marker="s", ms=5, mfc="none", mec=colour, zorder=3)
        else:
            ax.plot(x, y, "-", color=colour, lw=1.4, alpha=0.9, zorder=3)
            ax.plot(x[0], y[0], "o", ms=3, color=colour, zorder=3)
            ax.plot(x[-1], y[-1], ">", ms=4, color=colour, zorder=3)
        ax.annotate(str(tid), (x[-1], y[-1]), xytext=(3, 3), textcoords="offset points", fontsize=7,
                    color=colour, zorder=5)
    for cls in sorted(classes_drawn):
        handles.append(Line2D([], [], color=CLASS_COLOURS.get(cls, "tab:gray"), lw=2, label=CLASS_NAMES[cls]))

    size = 0.25
    if poses is not None:
        ax.plot(poses[:, 0], poses[:, 1], "-", color="black", lw=0.8, alpha=0.6, zorder=2)
        _sensor_marker(ax, poses[-1, 0], poses[-1, 1], poses[-1, 2], size)
    else:
        _sensor_marker(ax, 0.0, 0.0, 0.0, size)
    handles.append(Line2D([], [], marker=(3, 0, -90), ls="", color="black", label="scanner"))

    ax.autoscale_view()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    # figure shaped like the scene: a long corridor gets a wide, low figure; legend on the right
    fig.set_size_inches(11, float(np.clip(8 * (y1 - y0) / max(x1 - x0, 1e-6) + 1.3, 3.5, 9)))
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3, alpha=0.5)
    frame = "world (odom) frame" if world else "sensor frame"
    ax.set_xlabel(f"x (m), {frame}")
    ax.set_ylabel("y (m)")
    ax.set_title(title or Path(data.name).name)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.savefig(out, dpi=dpi)
    return out
