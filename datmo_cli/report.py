"""The per-run report: what a processed log saw, summarised from its decoded channels, and its formats.

Pure: `RunData.from_log` decodes an already-read log (no file access); `summarise` turns a RunData into a
RunSummary of plain dicts; `tables`, `render_rich`, `render_markdown`, `render_csv` and `to_json` format
summaries. Times in the report are seconds from the first scan; positions and distances in metres, in the
world (odometry) frame when the log has odometry, else in the sensor frame; speeds in m/s.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import MissingChannelError
from .log import cdr, mcapio, types

CLASS_NAMES = {0: "unknown", 1: "person", 2: "circle object", 3: "rectangular object"}
MOBILITY_NAMES = {0: "static", 1: "dynamic", 2: "undefined"}
LANDMARK_NAMES = {0: "corner", 1: "convex deflection", 2: "concave deflection", 3: "line end", 4: "column",
                  5: "bench"}
STATUS_TENTATIVE, STATUS_CONFIRMED, STATUS_COASTING = 0, 1, 2
SORT_KEYS = ("lifetime", "distance", "speed", "first", "id")
FORMATS = ("rich", "json", "csv", "markdown")


# ------------------------------------------------------------------------------------------- decoding


@dataclass
class Decoded:
    """One channel decoded into arrays: message k's elements of sequence field f are
    `items[f][offsets[f][k]:offsets[f][k + 1]]`; `scalars[name][k]` are its numeric scalar fields."""

    stamps: np.ndarray                              # (N,) int64, header stamps, ns
    frame_id: str
    scalars: dict[str, np.ndarray] = field(default_factory=dict)
    items: dict[str, np.ndarray] = field(default_factory=dict)
    offsets: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.stamps)

    def counts(self, name: str) -> np.ndarray:
        """Elements of sequence `name` in each message, (N,) int64."""
        return np.diff(self.offsets[name])

    def message_index(self, name: str) -> np.ndarray:
        """For each element of sequence `name`, the index of its message."""
        return np.repeat(np.arange(len(self.stamps)), self.counts(name))


def decode_channel(msgtype: str, payloads: list[bytes]) -> Decoded:
    """Decode every CDR payload of a flat datmo_msgs type into a Decoded."""
    decoded = [cdr.decode(msgtype, p) for p in payloads]
    stamps = np.array([d["stamp_ns"] for d in decoded], np.int64)
    out = Decoded(stamps, decoded[0]["frame_id"] if decoded else "")
    if not decoded:
        return out
    for name, value in decoded[0].items():
        if name in ("stamp_ns", "frame_id") or isinstance(value, str):
            continue
        if isinstance(value, np.ndarray) and value.dtype.names:
            parts = [d[name] for d in decoded]
            out.items[name] = np.concatenate(parts) if parts else np.zeros(0, value.dtype)
            out.offsets[name] = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
        elif not isinstance(value, np.ndarray):
            out.scalars[name] = np.array([d[name] for d in decoded])
    return out


def require(log: mcapio.LogContents, topic: str) -> None:
    """Raise MissingChannelError naming the command that makes `topic` when the log has no messages on it."""
    if not log.has(topic):
        maker = mcapio.PRODUCER.get(topic)
        hint = f"; run {maker} first" if maker else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")


@dataclass
class RunData:
    """The decoded channels of one processed log that the report, the plot and evaluate use."""

    name: str
    metadata: dict[str, dict[str, str]]
    scan_stamps: np.ndarray                 # (N,) int64 ns
    n_beams: int
    tracks: Decoded
    features: Decoded | None = None
    landmarks: Decoded | None = None
    ground_truth: Decoded | None = None
    scans: object | None = None             # log.scan.ScanRun, for the plot
    odometry: object | None = None          # log.scan.Odometry or None

    @classmethod
    def from_log(cls, log: mcapio.LogContents, *, keep_scans: bool = False) -> RunData:
        """Decode a log read with (at least) /scan and /datmo/tracks; the other channels when present.

        Raises MissingChannelError naming the command to run first when /scan or /datmo/tracks is absent.
        """
        require(log, mcapio.TOPIC_SCAN)
        require(log, mcapio.TOPIC_TRACKS)
        run = mcapio.run_from_log(log)

        def channel(topic: str, msgtype: str) -> Decoded | None:
            stamps, payloads = log.messages.get(topic, ([], []))
            return decode_channel(msgtype, payloads) if payloads else None

        return cls(name=str(log.path), metadata=log.metadata, scan_stamps=run.stamps, n_beams=run.geometry.n_beams,
                   tracks=channel(mcapio.TOPIC_TRACKS, types.TRACKS),
                   features=channel(mcapio.TOPIC_FEATURES, types.FEATURES),
                   landmarks=channel(mcapio.TOPIC_LANDMARKS, types.LANDMARKS),
                   ground_truth=channel(mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH),
                   scans=run if keep_scans else None, odometry=mcapio.odometry_from_log(log))


# -------------------------------------------------------------------------------------------- summary


@dataclass
class TrackHistory:
    """Every reported state of every track, sorted by track id then stamp; track ids[g] is rows
    starts[g]:starts[g + 1] of the per-state arrays below."""

    ids: np.ndarray          # (G,) track ids
    starts: np.ndarray       # (G + 1,)
    stamps: np.ndarray       # (M,) ns
    x: np.ndarray            # (M,) m, world frame when finite for the whole run, else sensor frame
    y: np.ndarray
    speed: np.ndarray        # (M,) m/s, |velocity| in the same frame
    states: np.ndarray       # (M,) Track elements
    world: bool              # True when x, y are world-frame


def track_history(tracks: Decoded, *, world: bool = True) -> TrackHistory:
    """Group the states of a /datmo/tracks channel by track id; positions in the world frame when `world`
    and every state has finite world coordinates, else in the sensor frame."""
    t = tracks.items.get("tracks", np.zeros(0, cdr.element_dtype(types.TRACK)))
    stamps = tracks.stamps[tracks.message_index("tracks")] if len(t) else np.zeros(0, np.int64)
    order = np.lexsort((stamps, t["id"]))
    t, stamps = t[order], stamps[order]
    world = world and bool(len(t)) and bool(np.isfinite(t["world_x"]).all() and np.isfinite(t["world_y"]).all())
    px, py, vx, vy = ("world_x", "world_y", "world_vx", "world_vy") if world else ("x", "y", "vx", "vy")
    ids, starts = np.unique(t["id"], return_index=True)
    return TrackHistory(ids, np.append(starts, len(t)).astype(np.int64), stamps, t[px].astype(np.float64),
                        t[py].astype(np.float64), np.hypot(t[vx], t[vy]).astype(np.float64), t, world)


def track_rows(h: TrackHistory, t0_ns: int) -> list[dict]:
    """One dict per track: class and mobility (its last state's); first, last and lifetime (s from t0, over
    every reported state); and over its confirmed states only (coasting predictions and tentative states
    are not observations): distance travelled (m, sum of steps between consecutive confirmed positions),
    mean and max filter speed (m/s); occlusions (episodes of consecutive occluded scans) and whether it
    was ever confirmed."""
    rows = []
    for g, tid in enumerate(h.ids.tolist()):
        a, b = int(h.starts[g]), int(h.starts[g + 1])
        st = h.states[a:b]
        conf = st["status"] == STATUS_CONFIRMED
        x, y, speed = h.x[a:b][conf], h.y[a:b][conf], h.speed[a:b][conf]
        occ = st["occluded"].astype(bool)
        t_first, t_last = (h.stamps[a] - t0_ns) / 1e9, (h.stamps[b - 1] - t0_ns) / 1e9
        rows.append({
            "id": tid, "class": CLASS_NAMES.get(int(st["classification"][-1]), "unknown"),
            "mobility": MOBILITY_NAMES.get(int(st["mobility"][-1]), "undefined"),
            "first_s": round(float(t_first), 3), "last_s": round(float(t_last), 3),
            "lifetime_s": round(float(t_last - t_first), 3), "scans": b - a,
            "distance_m": round(float(np.hypot(np.diff(x), np.diff(y)).sum()), 3),
            "mean_speed_mps": round(float(speed.mean()), 3) if len(speed) else 0.0,
            "max_speed_mps": round(float(speed.max()), 3) if len(speed) else 0.0,
            "occlusions": int(occ[0]) + int(np.sum(occ[1:] & ~occ[:-1])), "occluded_scans": int(occ.sum()),
            "confirmed": bool(conf.any()),
        })
    return rows


def class_rows(tracks: list[dict]) -> list[dict]:
    """Confirmed tracks grouped by (class, mobility): counts, lifetimes (s), distance (m), speeds (m/s)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in tracks:
        if r["confirmed"]:
            groups.setdefault((r["class"], r["mobility"]), []).append(r)
    order = {name: i for i, name in enumerate(CLASS_NAMES.values())}
    morder = {name: i for i, name in enumerate(("dynamic", "undefined", "static"))}
    out = []
    for (cls, mob), rs in sorted(groups.items(), key=lambda kv: (order[kv[0][0]], morder[kv[0][1]])):
        life = np.array([r["lifetime_s"] for r in rs])
        out.append({"class": cls, "mobility": mob, "tracks": len(rs),
                    "mean_lifetime_s": round(float(life.mean()), 3), "max_lifetime_s": round(float(life.max()), 3),
                    "distance_m": round(float(sum(r["distance_m"] for r in rs)), 3),
                    "mean_speed_mps": round(float(np.mean([r["mean_speed_mps"] for r in rs])), 3),
                    "max_speed_mps": round(float(max(r["max_speed_mps"] for r in rs)), 3),
                    "occlusions": int(sum(r["occlusions"] for r in rs))})
    return out


def run_facts(data: RunData) -> dict:
    """Duration (s), scans, rate (Hz, from the median period), beams, dropped scans (missing periods in
    the stamps' gaps), and the tool version, command and parameters of the file's provenance metadata."""
    st = data.scan_stamps
    dt = np.diff(st) / 1e9
    period = float(np.median(dt)) if len(dt) else 0.0
    dropped = int(np.sum(np.maximum(np.round(dt / period) - 1, 0))) if period > 0 else 0
    meta = data.metadata.get("datmo", {})
    params = {}
    for k, v in data.metadata.get("datmo.params", {}).items():
        try:
            params[k] = json.loads(v)
        except ValueError:
            params[k] = v
    return {"file": data.name, "duration_s": round(float((st[-1] - st[0]) / 1e9), 3) if len(st) else 0.0,
            "scans": int(len(st)), "rate_hz": round(1 / period, 3) if period > 0 else None,
            "beams": int(data.n_beams), "dropped_scans": dropped, "start_ns": int(st[0]) if len(st) else 0,
            "version": meta.get("version"), "command": meta.get("command_line") or meta.get("command"),
            "parameters": params}


def feature_facts(features: Decoded | None) -> dict | None:
    """Lines, circles and blobs: totals, mean and max per scan; None when the log has no features."""
    if features is None:
        return None
    out = {"scans": len(features)}
    for name in ("lines", "circles", "blobs"):
        c = features.counts(name) if name in features.offsets else np.zeros(len(features), np.int64)
        out[name] = {"total": int(c.sum()), "per_scan": round(float(c.mean()), 3) if len(c) else 0.0,
                     "max_per_scan": int(c.max()) if len(c) else 0}
    return out


def landmark_rows(landmarks: Decoded | None, t0_ns: int) -> list[dict] | None:
    """The landmark database after the last scan: id, type, position (m, in the channel's frame), first
    and last seen (s from t0), scans seen; None when the log has no landmarks channel."""
    if landmarks is None:
        return None
    if not len(landmarks) or "landmarks" not in landmarks.items:
        return []
    off = landmarks.offsets["landmarks"]
    db = landmarks.items["landmarks"][off[-2]:off[-1]]

    def secs(t: np.ndarray) -> float:
        return round((int(t["sec"]) * 1_000_000_000 + int(t["nanosec"]) - t0_ns) / 1e9, 3)

    return [{"id": int(lm["id"]), "type": LANDMARK_NAMES.get(int(lm["type"]), str(int(lm["type"]))),
             "x_m": round(float(lm["x"]), 3), "y_m": round(float(lm["y"]), 3), "size_m": round(float(lm["size"]), 3),
             "first_seen_s": secs(lm["first_seen"]), "last_seen_s": secs(lm["last_seen"]), "scans": int(lm["count"]),
             "frame": landmarks.frame_id} for lm in db]


@dataclass
class RunSummary:
    """Everything `datmo report` prints about one run (see the module docstring for units and frames)."""

    run: dict
    features: dict | None
    landmarks: list[dict] | None
    classes: list[dict]
    tracks: list[dict]          # every track, confirmed or not
    frame: str                  # "world" or "sensor": the frame of track positions and distances

    def confirmed(self) -> list[dict]:
        return [r for r in self.tracks if r["confirmed"]]

    def to_dict(self, top: int | None = None, sort: str = "lifetime") -> dict:
        tracks = sort_tracks(self.confirmed(), sort)
        return {"run": self.run, "features": self.features, "landmarks": self.landmarks,
                "tracks": {"frame": self.frame, "confirmed": len(tracks),
                           "tentative_only": len(self.tracks) - len(tracks), "by_class": self.classes,
                           "table": tracks[:top] if top else tracks}}

    def file_row(self) -> dict:
        """The one-row view used when several files are reported together."""
        conf = self.confirmed()
        f = self.features or {}
        row = {"file": self.run["file"], "duration_s": self.run["duration_s"], "scans": self.run["scans"]}
        for name in ("lines", "circles", "blobs"):
            row[f"{name}_per_scan"] = f[name]["per_scan"] if name in f else None
        row["landmarks"] = len(self.landmarks) if self.landmarks is not None else None
        row["tracks"] = len(conf)
        for cls in ("person", "circle object", "rectangular object", "unknown"):
            row[cls.replace(" ", "_")] = sum(r["class"] == cls for r in conf)
        row["dynamic"] = sum(r["mobility"] == "dynamic" for r in conf)
        row["distance_m"] = round(sum(r["distance_m"] for r in conf), 3)
        return row


def summarise(data: RunData) -> RunSummary:
    """The report of one run."""
    facts = run_facts(data)
    t0 = facts["start_ns"]
    hist = track_history(data.tracks)
    tracks = track_rows(hist, t0)
    return RunSummary(facts, feature_facts(data.features), landmark_rows(data.landmarks, t0), class_rows(tracks),
                      tracks, "world" if hist.world else "sensor")


def sort_tracks(rows: list[dict], key: str) -> list[dict]:
    """Tracks ordered by `key` (one of SORT_KEYS): longest, farthest, fastest first; `first` and `id` ascending."""
    col = {"lifetime": "lifetime_s", "distance": "distance_m", "speed": "max_speed_mps", "first": "first_s",
           "id": "id"}[key]
    descending = key in ("lifetime", "distance", "speed")
    return sorted(rows, key=lambda r: ((-r[col] if descending else r[col]), r["id"]))


def total_row(rows: list[dict]) -> dict:
    """Sum of file rows (per-scan figures weighted by scans)."""
    scans = sum(r["scans"] for r in rows)
    out = {"file": "total"}
    for k in rows[0]:
        if k == "file":
            continue
        vals = [r[k] for r in rows if r[k] is not None]
        if k.endswith("_per_scan"):
            ws = [r["scans"] for r in rows if r[k] is not None]
            out[k] = round(sum(v * w for v, w in zip(vals, ws, strict=True)) / sum(ws), 3) if sum(ws) else None
        elif not vals:
            out[k] = None
        else:
            out[k] = round(sum(vals), 3) if isinstance(vals[0], float) else sum(vals)
    out["scans"] = scans
    return out


# ----------------------------------------------------------------------------------------- formatting


@dataclass
class Table:
    """A titled table of plain values; formatted by render_rich, render_markdown and render_csv."""

    title: str
    columns: list[str]
    rows: list[list]
    numeric: set[int] = field(default_factory=set)  # column indices aligned right


def _cell(v: object) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.2f}"
    if isinstance(v, int):
        return f"{v:,}"
    return str(v)


def _table(title: str, rows: list[dict], columns: dict[str, str]) -> Table:
    keys = list(columns)
    values = [[r.get(k) for k in keys] for r in rows]
    numeric = {i for i, k in enumerate(keys)
               if any(isinstance(v[i], int | float) and not isinstance(v[i], bool) for v in values)}
    return Table(title, [columns[k] for k in keys], values, numeric)


TRACK_COLUMNS = {"id": "id", "class": "class", "mobility": "mobility", "first_s": "first s", "last_s": "last s",
                 "lifetime_s": "lifetime s", "distance_m": "distance m", "mean_speed_mps": "mean m/s",
                 "max_speed_mps": "max m/s", "occlusions": "occlusions"}
CLASS_COLUMNS = {"class": "class", "mobility": "mobility", "tracks": "tracks", "mean_lifetime_s": "mean lifetime s",
                 "max_lifetime_s": "max lifetime s", "distance_m": "distance m", "mean_speed_mps": "mean m/s",
                 "max_speed_mps": "max m/s", "occlusions": "occlusions"}
LANDMARK_COLUMNS = {"id": "id", "type": "type", "x_m": "x m", "y_m": "y m", "size_m": "size m",
                    "first_seen_s": "first seen s", "last_seen_s": "last seen s", "scans": "scans"}
FILE_COLUMNS = {"file": "file", "duration_s": "duration s", "scans": "scans", "lines_per_scan": "lines/scan",
                "circles_per_scan": "circles/scan", "blobs_per_scan": "blobs/scan", "landmarks": "landmarks",
                "tracks": "tracks", "person": "people", "circle_object": "circle obj.",
                "rectangular_object": "rect. obj.", "unknown": "unknown", "dynamic": "dynamic",
                "distance_m": "distance m"}


def tables(summary: RunSummary, top: int | None = 20, sort: str = "lifetime") -> list[Table]:
    """The tables of a one-run report: run facts, features, landmarks, tracks by class, the track table."""
    r = summary.run
    facts = [["file", r["file"]], ["duration", f"{r['duration_s']:.1f} s"], ["scans", r["scans"]],
             ["rate", f"{r['rate_hz']:.2f} Hz" if r["rate_hz"] else "-"], ["beams", r["beams"]],
             ["dropped scans", r["dropped_scans"]], ["datmo version", r["version"]], ["command", r["command"]]]
    facts += [[f"param {k}", json.dumps(v) if not isinstance(v, str) else v] for k, v in r["parameters"].items()]
    out = [Table("Run", ["what", "value"], facts)]
    f = summary.features
    if f is not None:
        out.append(Table(f"Features ({f['scans']:,} scans)", ["feature", "total", "per scan", "max per scan"],
                         [[n, f[n]["total"], f[n]["per_scan"], f[n]["max_per_scan"]]
                          for n in ("lines", "circles", "blobs")], {1, 2, 3}))
    if summary.landmarks is not None:
        frame = summary.landmarks[0]["frame"] if summary.landmarks else ""
        out.append(_table(f"Landmarks ({len(summary.landmarks)}, frame {frame or '-'})", summary.landmarks,
                          LANDMARK_COLUMNS))
    conf = summary.confirmed()
    tentative = len(summary.tracks) - len(conf)
    out.append(_table(f"Confirmed tracks by class ({len(conf)}; {tentative} never confirmed; "
                      f"{summary.frame} frame)", summary.classes, CLASS_COLUMNS))
    shown = sort_tracks(conf, sort)
    shown = shown[:top] if top else shown
    title = f"Tracks ({len(shown)} of {len(conf)}, by {sort})"
    out.append(_table(title, shown, TRACK_COLUMNS))
    return out


def file_table(summaries: list[RunSummary]) -> Table:
    """One row per file and a total row."""
    rows = [s.file_row() for s in summaries]
    return _table(f"{len(rows)} runs", rows + [total_row(rows)], FILE_COLUMNS)


def console():  # noqa: ANN201 - rich.console.Console, imported lazily
    """A rich console on stdout; 140 columns wide when stdout is not a terminal (files, pipes, CI logs)."""
    import sys

    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else 140)


def render_rich(tabs: list[Table], console) -> None:  # noqa: ANN001 - rich.console.Console, imported lazily
    """Print tables with rich."""
    from rich.table import Table as RichTable

    for t in tabs:
        rt = RichTable(title=t.title, title_justify="left")
        for i, c in enumerate(t.columns):
            rt.add_column(c, justify="right" if i in t.numeric else "left", overflow="fold")
        for row in t.rows:
            style = "bold" if row and row[0] == "total" else None
            rt.add_row(*(_cell(v) for v in row), style=style)
        if not t.rows:
            rt.add_row(*(["(none)"] + [""] * (len(t.columns) - 1)))
        console.print(rt)


def render_markdown(tabs: list[Table]) -> str:
    """GitHub-flavoured markdown: a heading and a pipe table per table."""
    parts = []
    for t in tabs:
        head = "| " + " | ".join(t.columns) + " |"
        rule = "|" + "|".join("---:" if i in t.numeric else "---" for i in range(len(t.columns))) + "|"
        body = ["| " + " | ".join(_cell(v).replace("|", "\\|") for v in row) + " |" for row in t.rows]
        parts.append("\n".join([f"### {t.title}", "", head, rule, *body]))
    return "\n\n".join(parts) + "\n"


def render_csv(table: Table, keys: list[str] | None = None) -> str:
    """One table as CSV with raw (unformatted) values; header = `keys` when given, else the column titles."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys or table.columns)
    for row in table.rows:
        w.writerow(["" if v is None else v for v in row])
    return buf.getvalue()


def to_json(obj: object) -> str:
    """JSON text; NaN and infinities become null."""
    def clean(o: object) -> object:
        if isinstance(o, float):
            return o if np.isfinite(o) else None
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, list | tuple):
            return [clean(v) for v in o]
        if isinstance(o, Path):
            return str(o)
        if isinstance(o, np.generic):
            return clean(o.item())
        return o

    return json.dumps(clean(obj), indent=2)


def render(summaries: list[RunSummary], fmt: str, *, top: int | None, sort: str, console=None) -> str | None:  # noqa: ANN001
    """A report of one or more runs in `fmt` (one of FORMATS). Returns the text, or prints to `console`
    (rich). One run: every table; csv gives the track table. Several runs: one row per file and a total
    row (json: every run's full report too)."""
    if top is None and fmt in ("rich", "markdown"):
        top = 20
    if len(summaries) == 1:
        s = summaries[0]
        if fmt == "json":
            return to_json(s.to_dict(top, sort))
        if fmt == "csv":
            rows = sort_tracks(s.confirmed(), sort)
            rows = rows[:top] if top else rows
            keys = list(TRACK_COLUMNS) + ["occluded_scans", "scans"]
            return render_csv(Table("tracks", keys, [[r[k] for k in keys] for r in rows]))
        tabs = tables(s, top, sort)
    else:
        ft = file_table(summaries)
        if fmt == "json":
            rows = [s.file_row() for s in summaries]
            return to_json({"files": rows, "total": total_row(rows),
                            "runs": [s.to_dict(top, sort) for s in summaries]})
        if fmt == "csv":
            return render_csv(ft, list(FILE_COLUMNS))
        tabs = [ft]
    if fmt == "markdown":
        return render_markdown(tabs)
    render_rich(tabs, console)
    return None
