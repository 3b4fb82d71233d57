"""The run drawn for a reader: from above like Fig. 7c of Castro, Nunes and Ruano (2004), and over time.

The top view leads with what moves: faded scan points, the named landmarks, the trajectories of people
and dynamic tracks coloured by class with their ids, the static pieces (walls, furniture) as small
unlabelled squares where they were last seen (labelled too with `all_labels`), and the scanner's pose.
Labels never overlap: each is placed at the first of a few offsets around its point where its box meets
no label placed before it (people first, then the longest-lived tracks), or left out (`Drawn.dropped`).
Beside it, `counts` draws the confirmed tracks per class over time, `speeds` the moving tracks' speeds.

Everything is drawn in the world (odometry) frame when the log has odometry and world-frame tracks,
else in the sensor frame. Metres, seconds from the first scan, m/s. matplotlib is imported here only,
with the Agg canvas (no display).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_NAMES,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    LANDMARK_BENCH,
    LANDMARK_COLUMN,
    LANDMARK_CONCAVE_DEFLECTION,
    LANDMARK_CONVEX_DEFLECTION,
    LANDMARK_CORNER,
    LANDMARK_LINE_END,
    LANDMARK_NAMES,
    MOBILITY_DYNAMIC,
    STATUS_CONFIRMED,
    STATUS_TENTATIVE,
)
from . import RunData, TrackHistory, track_history

CLASS_COLOURS = {
    CLASS_UNKNOWN: "tab:gray",
    CLASS_PERSON: "tab:red",
    CLASS_CIRCLE_OBJECT: "tab:blue",
    CLASS_RECTANGULAR_OBJECT: "tab:green",
}
LANDMARK_MARKERS = {
    LANDMARK_CORNER: "v",
    LANDMARK_CONVEX_DEFLECTION: "^",
    LANDMARK_CONCAVE_DEFLECTION: "<",
    LANDMARK_LINE_END: "x",
    LANDMARK_COLUMN: "o",
    LANDMARK_BENCH: "s",
}
FORMATS = (".png", ".svg", ".pdf")
KINDS = ("auto", "top", "counts", "speeds", "all")
# label offsets from the point (points) and the text's alignment there: the four diagonals first
LABEL_SPOTS = [
    (dx * r, dy * r, ha, va)
    for r in (3, 9)
    for dx, dy, ha, va in (
        (1, 1, "left", "bottom"),
        (1, -1, "left", "top"),
        (-1, 1, "right", "bottom"),
        (-1, -1, "right", "top"),
        (2, 0, "left", "center"),
        (-2, 0, "right", "center"),
        (0, 2, "center", "bottom"),
        (0, -2, "center", "top"),
    )
]


@dataclass
class Drawn:
    """A drawn figure: the kind drawn (auto resolved), its id labels (matplotlib Text, in the top view) and
    how many labels were placed and left out for want of room."""

    figure: Any  # a matplotlib Figure
    kind: str
    labels: list = field(default_factory=list)
    placed: int = 0
    dropped: int = 0


@dataclass
class TrackLines:
    """Each confirmed track of a TrackHistory: its slice, class, whether it moves (a person or dynamic, by
    its last state, as the report says) and its confirmed states."""

    groups: list[tuple[int, int, int]]  # (track id, start, end) rows of the history
    classes: list[int]
    moving: list[bool]
    confirmed: list[np.ndarray]  # bool per state of the slice


def track_lines(hist: TrackHistory) -> TrackLines:
    """The confirmed tracks of `hist` (tracks never confirmed are not drawn)."""
    out = TrackLines([], [], [], [])
    for g, tid in enumerate(hist.ids.tolist()):
        a, b = int(hist.starts[g]), int(hist.starts[g + 1])
        st = hist.states[a:b]
        conf = st["status"] == STATUS_CONFIRMED
        if not conf.any():
            continue
        cls = int(st["classification"][-1])
        out.groups.append((tid, a, b))
        out.classes.append(cls)
        out.moving.append(cls == CLASS_PERSON or int(st["mobility"][-1]) == MOBILITY_DYNAMIC)
        out.confirmed.append(conf)
    return out


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


def _sensor_marker(ax, x: float, y: float, theta: float, size: float) -> None:
    from matplotlib.patches import Polygon

    tri = np.array([[1.0, 0.0], [-0.6, 0.55], [-0.6, -0.55]]) * size
    c, s = np.cos(theta), np.sin(theta)
    pts = tri @ np.array([[c, s], [-s, c]]) + [x, y]
    ax.add_patch(Polygon(pts, closed=True, facecolor="black", edgecolor="black", zorder=6, label="scanner"))


def _top_view(
    ax, data: RunData, hist: TrackHistory, lines: TrackLines, max_points: int, all_labels: bool
) -> list[tuple[int, float, float, str]]:
    """Draw the run from above into `ax`; return the labels to place (id, x, y, colour), most important first."""
    from matplotlib.lines import Line2D

    world = hist.world
    px, py, poses = _scan_points(data, world, max_points)
    ax.scatter(px, py, s=0.6, c="0.55", alpha=0.15, linewidths=0, rasterized=True, zorder=1)
    handles = [Line2D([], [], marker=".", ls="", color="0.55", label="scan points")]
    if data.landmarks is not None and len(data.landmarks) and "landmarks" in data.landmarks.items:
        off = data.landmarks.offsets["landmarks"]
        db = data.landmarks.items["landmarks"][off[-2] : off[-1]]
        for typ in sorted(set(db["type"].tolist())):
            sel = db[db["type"] == typ]
            m = LANDMARK_MARKERS.get(typ, "*")
            hollow = m in "os^v<D"
            style = {"facecolors": "none", "edgecolors": "black"} if hollow else {"c": "black"}
            ax.scatter(sel["x"], sel["y"], marker=m, s=70, linewidths=1.3, zorder=4, **style)
            handles.append(
                Line2D([], [], marker=m, ls="", mfc="none", mec="black", label=LANDMARK_NAMES.get(typ, str(typ)))
            )

    labels = []
    for (tid, a, b), cls, moves, conf in zip(lines.groups, lines.classes, lines.moving, lines.confirmed, strict=True):
        colour = CLASS_COLOURS.get(cls, "tab:gray")
        # confirmed states only, the line broken where the track coasted (predictions, not observations)
        x, y = np.where(conf, hist.x[a:b], np.nan), np.where(conf, hist.y[a:b], np.nan)
        first, last = np.flatnonzero(conf)[[0, -1]]
        x, y = x[first : last + 1], y[first : last + 1]
        if moves:
            ax.plot(x, y, "-", color=colour, lw=1.4, alpha=0.9, zorder=3)
            ax.plot(x[0], y[0], "o", ms=3, color=colour, zorder=3)
            ax.plot(x[-1], y[-1], ">", ms=4, color=colour, zorder=3)
        else:
            ax.plot(x[-1], y[-1], marker="s", ms=4, mfc="none", mec=colour, alpha=0.6, zorder=2)
        if moves or all_labels:
            priority = (not moves, cls != CLASS_PERSON, -int(conf.sum()), tid)
            labels.append((priority, (tid, float(x[-1]), float(y[-1]), colour)))
    for cls in sorted(set(lines.classes)):
        handles.append(Line2D([], [], color=CLASS_COLOURS.get(cls, "tab:gray"), lw=2, label=CLASS_NAMES[cls]))
    if any(not m for m in lines.moving):
        handles.append(Line2D([], [], marker="s", ls="", mfc="none", mec="tab:gray", label="static pieces"))

    size = 0.25
    if poses is not None:
        ax.plot(poses[:, 0], poses[:, 1], "-", color="black", lw=0.8, alpha=0.6, zorder=2)
        _sensor_marker(ax, poses[-1, 0], poses[-1, 1], poses[-1, 2], size)
    else:
        _sensor_marker(ax, 0.0, 0.0, 0.0, size)
    handles.append(Line2D([], [], marker=(3, 0, -90), ls="", color="black", label="scanner"))
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_xlabel(f"x (m), {'world (odom) frame' if world else 'sensor frame'}")
    ax.set_ylabel("y (m)")
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    return [label for _, label in sorted(labels, key=lambda pl: pl[0])]


def _seconds(data: RunData, stamps: np.ndarray) -> np.ndarray:
    t0 = data.scan_stamps[0] if len(data.scan_stamps) else (stamps[0] if len(stamps) else 0)
    return (stamps - t0) / 1e9


def _counts(ax, data: RunData, hist: TrackHistory, lines: TrackLines) -> None:
    """Tracks per class over time (confirmed tracks' confirmed and coasting states, so a track does not
    blink out while it coasts): moving ones per class, static pieces together (dotted)."""
    stamps = np.unique(hist.stamps)
    t = _seconds(data, stamps)
    series: dict[tuple[bool, int], np.ndarray] = {}
    for (_, a, b), cls, moves in zip(lines.groups, lines.classes, lines.moving, strict=True):
        key = (moves, cls if moves else -1)
        counts = series.setdefault(key, np.zeros(len(stamps), np.int64))
        alive = hist.states["status"][a:b] != STATUS_TENTATIVE  # confirmed or coasting: still followed
        np.add.at(counts, np.searchsorted(stamps, hist.stamps[a:b][alive]), 1)
    for (moves, cls), counts in sorted(series.items(), key=lambda kv: (not kv[0][0], kv[0][1])):
        if moves:
            ax.step(
                t,
                counts,
                where="post",
                color=CLASS_COLOURS.get(cls, "tab:gray"),
                lw=1.2,
                label=f"{CLASS_NAMES[cls]}, moving",
            )
        else:
            ax.step(t, counts, where="post", color="0.4", lw=1.0, ls=":", label="static pieces")
    ax.set_ylabel("confirmed tracks")
    ax.set_title("tracks per class over time", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    if series:
        ax.legend(fontsize=7, frameon=False, loc="upper right")


def _speeds(ax, data: RunData, hist: TrackHistory, lines: TrackLines) -> None:
    """The filter speed of each moving track over its confirmed states, coloured by class."""
    drawn = set()
    for (_, a, b), cls, moves, conf in zip(lines.groups, lines.classes, lines.moving, lines.confirmed, strict=True):
        if not moves:
            continue
        speed = np.where(conf, hist.speed[a:b], np.nan)
        ax.plot(
            _seconds(data, hist.stamps[a:b]),
            speed,
            "-",
            lw=0.9,
            alpha=0.8,
            color=CLASS_COLOURS.get(cls, "tab:gray"),
            label=None if cls in drawn else CLASS_NAMES[cls],
        )
        drawn.add(cls)
    ax.set_xlabel("time (s) from the first scan")
    ax.set_ylabel("speed (m/s)")
    ax.set_title("speeds of people and dynamic tracks", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    if drawn:
        ax.legend(fontsize=7, frameon=False, loc="upper right")


def place_labels(ax, labels: list[tuple[int, float, float, str]]) -> tuple[list, int]:
    """Put each label (id, x, y, colour; in order) at the first spot of LABEL_SPOTS around its point where it
    stays inside the axes and its box, padded by a pixel, meets no label placed before; leave it out when
    there is none. Needs the figure's layout done (Figure.draw_without_rendering). Returns the placed
    Texts and how many were left out."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    placed: list[Any] = []
    boxes: list[Any] = []
    dropped = 0
    for tid, x, y, colour in labels:
        text = None
        for dx, dy, ha, va in LABEL_SPOTS:
            if text is None:
                text = ax.annotate(
                    str(tid),
                    (x, y),
                    xytext=(dx, dy),
                    textcoords="offset points",
                    fontsize=7,
                    color=colour,
                    ha=ha,
                    va=va,
                    zorder=5,
                    annotation_clip=True,
                )
                text.set_in_layout(False)
            else:
                text.set_position((dx, dy))
                text.set_ha(ha)
                text.set_va(va)
            box = text.get_window_extent(renderer).padded(1.0)
            inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
            if inside and not any(box.overlaps(b) for b in boxes):
                boxes.append(box)
                placed.append(text)
                break
        else:
            if text is not None:
                text.remove()
            dropped += 1
    return placed, dropped


def draw(
    data: RunData, *, kind: str = "auto", all_labels: bool = False, title: str | None = None, max_points: int = 150_000
) -> Drawn:
    """Draw `data` (a RunData with scans kept) as `kind` (KINDS; auto: all when a confirmed track moves,
    else top) into a new Figure, labels placed (place_labels)."""
    from ..base.extras import require

    require("matplotlib", for_="drawing a run")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    # Scan points can be put in the world frame only with odometry; tracks follow the scan points' frame.
    hist = track_history(data.tracks, world=data.odometry is not None)
    lines = track_lines(hist)
    if kind == "auto":
        kind = "all" if any(lines.moving) else "top"
    name = title or Path(data.name).name
    fig = Figure(figsize=(11, 8), layout="constrained")
    FigureCanvasAgg(fig)
    if kind in ("counts", "speeds"):
        fig.set_size_inches(10, 4)
        ax = fig.add_subplot()
        (_counts if kind == "counts" else _speeds)(ax, data, hist, lines)
        if kind == "counts":
            ax.set_xlabel("time (s) from the first scan")
        fig.suptitle(name)
        return Drawn(fig, kind)
    if kind == "top":
        top = fig.add_subplot()
    else:
        grid = fig.add_gridspec(2, 2, width_ratios=(3, 2))
        top = fig.add_subplot(grid[:, 0])
        counts = fig.add_subplot(grid[0, 1])
        speeds = fig.add_subplot(grid[1, 1], sharex=counts)
        _counts(counts, data, hist, lines)
        _speeds(speeds, data, hist, lines)
    labels = _top_view(top, data, hist, lines, max_points, all_labels)
    (x0, x1), (y0, y1) = top.get_xlim(), top.get_ylim()
    # figure shaped like the scene: a long corridor gets a wide, low figure; legend on the right
    height = float(np.clip(8 * (y1 - y0) / max(x1 - x0, 1e-6) + 1.3, 3.5, 9))
    if kind == "top":
        fig.set_size_inches(11, height)
    else:
        fig.set_size_inches(17, max(height, 6.0))
    top.set_title(name)
    fig.draw_without_rendering()  # the layout and the equal aspect's limits, before labels are measured
    placed, dropped = place_labels(top, labels)
    if dropped:
        top.set_title(f"{name} ({dropped} of {dropped + len(placed)} labels left out: no room without overlap)")
    return Drawn(fig, kind, placed, len(placed), dropped)


def plot_run(
    data: RunData,
    out: str | Path | IO[bytes],
    *,
    kind: str = "auto",
    all_labels: bool = False,
    title: str | None = None,
    max_points: int = 150_000,
    dpi: int = 150,
) -> Drawn:
    """Draw `data` (see `draw`) into `out` (.png, .svg or .pdf; or an open file, in the format
    rcParams["savefig.format"] says)."""
    drawn = draw(data, kind=kind, all_labels=all_labels, title=title, max_points=max_points)
    drawn.figure.savefig(out if hasattr(out, "write") else Path(out), dpi=dpi)
    return drawn
