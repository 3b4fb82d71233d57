"""A small processed log written by hand, with known answers, for the report and evaluate tests.

Static scanner at the origin of a 9 m x 8 m room, 50 scans at 5 Hz (10 s), no odometry. Ground truth:
  person 1   from (2, -3) walking +y at 0.6 m/s, always visible
  person 2   from (5, 3) walking -y at 0.5 m/s, hidden (visible = 0) in scans 20-24
  circle 3   from (4, 0) moving +x at 0.2 m/s, always visible
  column 4   at (6, -2), class column (not a mover)
Tracks (positions = truth + (0.03, 0.04), so every match is 0.05 m away):
  1  person 1, tentative in scans 0-1, then confirmed; person, dynamic
  2  person 2, scans 0-19 confirmed, 20-24 coasting and occluded; person, dynamic
  7  person 2 again from scan 25 (an identity switch); person, dynamic
  3  circle 3 from scan 10 only (10 misses); circle object, dynamic
  4  a false object at (7, 1) in scans 30-39, confirmed; rectangular object, dynamic (10 false positives)
  5  the column, confirmed, rectangular object, static (ignored: it lies in the column's don't-care region)
  6  tentative only, scans 5-6 at (3, 3)
Scored by default (visible moving movers, confirmed tracks): 145 objects, 133 matches, 12 misses,
10 false positives, 1 switch, 50 ignored hypotheses (track 5); MOTA = 1 - 23/145.
"""

from __future__ import annotations

import numpy as np

from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun

N = 50
T0 = 1_600_000_000_000_000_000
STAMPS = T0 + np.arange(N, dtype=np.int64) * 200_000_000
GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")
OFFSET = np.array([0.03, 0.04])
EXPECTED = {
    "objects": 145,
    "matches": 133,
    "misses": 12,
    "false_positives": 10,
    "switches": 1,
    "mota": 1 - 23 / 145,
    "motp": 0.05,
    "ignored": 50,
}


def room_ranges() -> np.ndarray:
    """Ranges (N x 361, m) of a static scanner at (0, 0) facing +x in the room x in [-1, 8], y in [-4, 4]."""
    a = GEOM.angles()
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        candidates = np.stack(
            [np.where(c > 0, 8 / c, np.inf), np.where(s > 0, 4 / s, np.inf), np.where(s < 0, -4 / s, np.inf)]
        )
    r = np.minimum(candidates.min(0), 7.99).astype(np.float32)
    return np.tile(r, (N, 1))


def truth(k: int) -> np.ndarray:
    """Ground-truth objects of scan k."""
    t = k * 0.2
    gt = np.zeros(4, cdr.element_dtype(types.GROUND_TRUTH_OBJECT))
    gt["id"] = [1, 2, 3, 4]
    gt["classification"] = [1, 1, 2, 4]
    gt["x"] = [2.0, 5.0, 4.0 + 0.2 * t, 6.0]
    gt["y"] = [-3.0 + 0.6 * t, 3.0 - 0.5 * t, 0.0, -2.0]
    gt["vx"] = [0, 0, 0.2, 0]
    gt["vy"] = [0.6, -0.5, 0, 0]
    gt["world_x"], gt["world_y"] = gt["x"], gt["y"]
    gt["visible"] = [1, 0 if 20 <= k <= 24 else 1, 1, 1]
    gt["n_beams"] = gt["visible"] * 6
    gt["moving"] = [1, 1, 1, 0]
    gt["length"] = gt["width"] = [0.87, 0.87, 0.5, 0.3]
    return gt


def tracks(k: int) -> np.ndarray:
    """Track states after scan k (see the module docstring)."""
    g = {int(o["id"]): o for o in truth(k)}
    rows = []

    def add(tid: int, gid: int | None, cls: int, mob: int, status: int, occluded: int = 0, xy=None) -> None:
        x, y = (g[gid]["x"] + OFFSET[0], g[gid]["y"] + OFFSET[1]) if gid else xy
        vx, vy = (g[gid]["vx"], g[gid]["vy"]) if gid else (0.0, 0.0)
        rows.append((tid, cls, mob, status, occluded, x, y, vx, vy))

    add(1, 1, 1, 1, 0 if k < 2 else 1)
    if k < 20:
        add(2, 2, 1, 1, 1)
    elif k < 25:
        add(2, 2, 1, 1, 2, occluded=1)
    else:
        add(7, 2, 1, 1, 1)
    if k >= 10:
        add(3, 3, 2, 1, 1)
    if 30 <= k < 40:
        add(4, None, 3, 1, 1, xy=(7.0, 1.0))
    add(5, 4, 3, 0, 1)
    if k in (5, 6):
        add(6, None, 0, 2, 0, xy=(3.0, 3.0))
    out = np.zeros(len(rows), cdr.element_dtype(types.TRACK))
    for i, (tid, cls, mob, status, occ, x, y, vx, vy) in enumerate(rows):
        out[i]["id"], out[i]["classification"], out[i]["mobility"], out[i]["status"] = tid, cls, mob, status
        out[i]["occluded"], out[i]["x"], out[i]["y"], out[i]["vx"], out[i]["vy"] = occ, x, y, vx, vy
        out[i]["world_x"] = out[i]["world_y"] = out[i]["world_vx"] = out[i]["world_vy"] = np.nan
        out[i]["age"] = out[i]["hits"] = k
        out[i]["size"] = 0.2
    return out


def features(k: int) -> dict:
    lines = np.zeros(2, cdr.element_dtype(types.LINE))
    circles = np.zeros(k % 3, cdr.element_dtype(types.CIRCLE))
    blobs = np.zeros(1, cdr.element_dtype(types.BLOB))
    return {"lines": lines, "circles": circles, "blobs": blobs}


def landmarks(k: int) -> np.ndarray:
    dt = cdr.element_dtype(types.LANDMARK)
    rows = []
    if k >= 10:
        rows.append((1, 4, 6.0, -2.0, 0.15, 10))
    if k >= 20:
        rows.append((2, 0, 8.0, 4.0, 0.0, 20))
    out = np.zeros(len(rows), dt)
    for i, (lid, typ, x, y, size, first) in enumerate(rows):
        out[i]["id"], out[i]["type"], out[i]["x"], out[i]["y"], out[i]["size"] = lid, typ, x, y, size
        out[i]["count"] = k - first + 1
        out[i]["first_seen"]["sec"], out[i]["first_seen"]["nanosec"] = divmod(int(STAMPS[first]), 1_000_000_000)
        out[i]["last_seen"]["sec"], out[i]["last_seen"]["nanosec"] = divmod(int(STAMPS[k]), 1_000_000_000)
    return out


def write(
    path,
    *,
    with_tracks: bool = True,
    with_truth: bool = True,
    with_features: bool = True,
    drop_scans: tuple[int, ...] = (),
) -> None:
    """Write the synthetic processed log to `path` (optionally without some channels or some scans)."""
    keep = np.array([k for k in range(N) if k not in drop_scans])
    run = ScanRun(STAMPS[keep], room_ranges()[keep], GEOM)
    with mcapio.LogWriter(
        path,
        provenance=mcapio.Provenance("track", {"gate_m": 1.5, "c0": 0.05}, command_line="datmo track in.mcap -o x"),
    ) as w:
        w.write_scans(run)
        for k in keep.tolist():
            s = int(STAMPS[k])
            if with_truth:
                w.write(
                    mcapio.TOPIC_GROUND_TRUTH,
                    types.GROUND_TRUTH,
                    s,
                    cdr.encode(types.GROUND_TRUTH, {"stamp_ns": s, "frame_id": "laser", "objects": truth(k)}),
                )
            if with_features:
                w.write(
                    mcapio.TOPIC_FEATURES,
                    types.FEATURES,
                    s,
                    cdr.encode(types.FEATURES, {"stamp_ns": s, "frame_id": "laser", **features(k)}),
                )
                w.write(
                    mcapio.TOPIC_LANDMARKS,
                    types.LANDMARKS,
                    s,
                    cdr.encode(types.LANDMARKS, {"stamp_ns": s, "frame_id": "laser", "landmarks": landmarks(k)}),
                )
            if with_tracks:
                w.write(
                    mcapio.TOPIC_TRACKS,
                    types.TRACKS,
                    s,
                    cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": "laser", "tracks": tracks(k)}),
                )


def fill_report(report, path) -> None:
    """Give a report.RunAccumulator what the pipeline would feed it while writing the log at `path` (for the
    stand-ins of pipeline.process_file: here it is read back from the synthetic log)."""
    from datmo_cli.report import stream_run

    name = report.name
    report.__dict__.update(stream_run(path).__dict__)
    report.name = name
