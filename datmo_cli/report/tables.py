"""The report's tables and shapes: the columns of each table, the JSON and CSV shapes (REPORT_SCHEMA), and
the tables of one file (`file_tables`) and of several (`file_table`, `total_row`), as plain values (`Table`)
that report.formats prints."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from .summary import RunSummary, moving, static_rows


@dataclass
class Table:
    """A titled table of plain values; formatted by render_rich, render_markdown and render_csv."""

    title: str
    columns: list[str]
    rows: list[list]
    numeric: set[int] = field(default_factory=set)  # column indices aligned right


def _table(title: str, rows: list[dict], columns: dict[str, str]) -> Table:
    keys = list(columns)
    values = [[r.get(k) for k in keys] for r in rows]
    numeric = {
        i
        for i, k in enumerate(keys)
        if any(isinstance(v[i], int | float) and not isinstance(v[i], bool) for v in values)
    }
    return Table(title, [columns[k] for k in keys], values, numeric)


SCHEMA = "datmo.report/1"
TRACK_COLUMNS = {
    "id": "id",
    "class": "class",
    "mobility": "mobility",
    "first_s": "first s",
    "last_s": "last s",
    "lifetime_s": "lifetime s",
    "distance_m": "distance m",
    "mean_speed_mps": "mean m/s",
    "max_speed_mps": "max m/s",
    "occlusions": "occlusions",
    "x_m": "last x m",
    "y_m": "last y m",
}
STATIC_COLUMNS = {
    "class": "class",
    "mobility": "mobility",
    "tracks": "tracks",
    "mean_lifetime_s": "mean lifetime s",
    "centroid_x_m": "centroid x m",
    "centroid_y_m": "centroid y m",
    "x_min_m": "x min m",
    "x_max_m": "x max m",
    "y_min_m": "y min m",
    "y_max_m": "y max m",
}
LANDMARK_COLUMNS = {
    "id": "id",
    "type": "type",
    "x_m": "x m",
    "y_m": "y m",
    "size_m": "size m",
    "first_seen_s": "first seen s",
    "last_seen_s": "last seen s",
    "scans": "scans",
}
FILE_COLUMNS = {
    "file": "file",
    "duration_s": "duration s",
    "scans": "scans",
    "lines_per_scan": "lines/scan",
    "circles_per_scan": "circles/scan",
    "blobs_per_scan": "blobs/scan",
    "landmarks": "landmarks",
    "tracks": "tracks",
    "moving": "moving",
    "static_pieces": "static pieces",
    "person": "people",
    "circle_object": "circle obj.",
    "rectangular_object": "rect. obj.",
    "unknown": "unknown",
    "dynamic": "dynamic",
    "distance_m": "distance m",
}
# `--format csv --tracks`: one row per track of every file
TRACK_CSV_KEYS = ["file", *TRACK_COLUMNS, "occluded_scans", "scans"]
REPORT_SCHEMA = f"""The report's shapes, the same for one file, several files, batch folders and datmo run's report:

csv            one row per file, then a row whose file is "total"; header:
               {",".join(FILE_COLUMNS)}
csv --tracks   one row per confirmed track (static pieces too), with a file column; header:
               {",".join(TRACK_CSV_KEYS)}
json           {{"schema": "{SCHEMA}", "files": [FILE...], "total": ROW, "batches": [BATCH...],
                 "tracks": [TRACK...] (with --tracks only)}}
               FILE: the file's csv row plus "run" (facts, provenance), "features", "landmark_list" (the
               landmark database; null without /datmo/landmarks), "frame", "tentative_only", "classes"
               (confirmed tracks by class and mobility), "moving_tracks" (people and dynamic tracks in full)
               and "static_by_class" (the other confirmed tracks per class and mobility: count, centroid,
               bounding box); BATCH: {{"folder", "summary", "inputs"}} of a batch folder's manifest.jsonl;
               TRACK: a csv --tracks row.
Moving: a person, or a track whose mobility is dynamic. Times in s from the file's first scan; positions
in m in the world frame when every track state has one, else the sensor frame; speeds in m/s."""


PARAM_WIDTH = 160  # characters of a text cell the rich report shows on a terminal; piped, cells are whole


def param_text(name: str, value) -> str:
    """A parameter's value as the run table shows it: the leg model by its name, digest and threshold (its
    record holds the training figures), any other value as JSON, whole (on a terminal the rich report cuts it
    at PARAM_WIDTH characters)."""
    if name == "leg_model" and isinstance(value, dict) and "sha256" in value:
        threshold = value.get("threshold")
        about = f", threshold {threshold:.2f}" if isinstance(threshold, float) else ""
        return f"{value.get('model') or value.get('path')} (sha256 {str(value['sha256'])[:12]}{about})"
    text = value if isinstance(value, str) else json.dumps(value)
    return text


def file_tables(
    summary: RunSummary, top: int | None = 20, sort: str = "lifetime", all_tracks: bool = False
) -> list[Table]:
    """The tables of one file: run facts, features, landmarks, the tracks in full (the moving ones, or every
    confirmed one with `all_tracks`) and the static pieces per class."""
    r = summary.run
    name = Path(r["file"]).name
    facts = [
        ["file", r["file"]],
        ["duration", f"{r['duration_s']:.1f} s"],
        ["scans", r["scans"]],
        ["rate", f"{r['rate_hz']:.2f} Hz" if r["rate_hz"] else "-"],
        ["beams", r["beams"]],
        ["dropped scans", r["dropped_scans"]],
        ["datmo version", r["version"]],
        ["command", r["command"]],
    ]
    facts += [[f"param {k}", param_text(k, v)] for k, v in r["parameters"].items()]
    out = [Table(f"{name}: run", ["what", "value"], facts)]
    f = summary.features
    if f is not None:
        out.append(
            Table(
                f"{name}: features ({f['scans']:,} scans)",
                ["feature", "total", "per scan", "max per scan"],
                [[n, f[n]["total"], f[n]["per_scan"], f[n]["max_per_scan"]] for n in ("lines", "circles", "blobs")],
                {1, 2, 3},
            )
        )
    if summary.landmarks is not None:
        frame = summary.landmarks[0]["frame"] if summary.landmarks else ""
        out.append(
            _table(
                f"{name}: landmarks ({len(summary.landmarks)}, frame {frame or '-'})",
                summary.landmarks,
                LANDMARK_COLUMNS,
            )
        )
    conf = summary.confirmed()
    n_moving = sum(moving(t) for t in conf)
    shown = summary.shown(top, sort, all_tracks)
    what = "confirmed tracks" if all_tracks else "people and dynamic tracks"
    of = len(conf) if all_tracks else n_moving
    out.append(
        _table(
            f"{name}: {what} ({len(shown)} of {of}, by {sort}; {len(conf)} confirmed, "
            f"{len(summary.tracks) - len(conf)} never confirmed; {summary.frame} frame)",
            shown,
            TRACK_COLUMNS,
        )
    )
    statics = static_rows(summary.tracks)
    out.append(
        _table(
            f"{name}: static pieces by class ({len(conf) - n_moving} tracks; where they were last seen)",
            statics,
            STATIC_COLUMNS,
        )
    )
    return out


def file_table(summaries: list[RunSummary]) -> Table:
    """One row per file and a total row."""
    rows = [s.file_row() for s in summaries]
    return _table(f"{len(rows)} file{'s' if len(rows) != 1 else ''}", rows + [total_row(rows)], FILE_COLUMNS)


def total_row(rows: list[dict]) -> dict:
    """Sum of file rows (per-scan figures weighted by scans); zeros and None when there are none."""
    out: dict = {"file": "total"}
    for k in FILE_COLUMNS:
        if k == "file":
            continue
        vals = [r[k] for r in rows if r[k] is not None]
        if k.endswith("_per_scan"):
            ws = [r["scans"] for r in rows if r[k] is not None]
            out[k] = round(sum(v * w for v, w in zip(vals, ws, strict=True)) / sum(ws), 3) if sum(ws) else None
        elif not vals:
            out[k] = None if rows else (0.0 if k.endswith(("_s", "_m")) else 0)
        else:
            out[k] = round(sum(vals), 3) if isinstance(vals[0], float) else sum(vals)
    return out
