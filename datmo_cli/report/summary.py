"""The summary of one run as plain dicts (`RunSummary`), and the rows made of its tracks: by class and
mobility (`class_rows`), the static pieces (`static_rows`), the moving ones (`moving`), in report order
(`sort_tracks`). Times in s from the first scan; positions and distances in m, in the frame `RunSummary.frame`
names; speeds in m/s."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_NAMES,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
    MOBILITY_NAMES,
    MOBILITY_STATIC,
    MOBILITY_UNDEFINED,
)

SORT_KEYS = ("lifetime", "distance", "speed", "first", "id")


def class_rows(tracks: list[dict]) -> list[dict]:
    """Confirmed tracks grouped by (class, mobility): counts, lifetimes (s), distance (m), speeds (m/s)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in tracks:
        if r["confirmed"]:
            groups.setdefault((r["class"], r["mobility"]), []).append(r)
    order = {name: i for i, name in enumerate(CLASS_NAMES.values())}
    morder = {MOBILITY_NAMES[m]: i for i, m in enumerate((MOBILITY_DYNAMIC, MOBILITY_UNDEFINED, MOBILITY_STATIC))}
    out = []
    for (cls, mob), rs in sorted(groups.items(), key=lambda kv: (order[kv[0][0]], morder[kv[0][1]])):
        life = np.array([r["lifetime_s"] for r in rs])
        out.append(
            {
                "class": cls,
                "mobility": mob,
                "tracks": len(rs),
                "mean_lifetime_s": round(float(life.mean()), 3),
                "max_lifetime_s": round(float(life.max()), 3),
                "distance_m": round(float(sum(r["distance_m"] for r in rs)), 3),
                "mean_speed_mps": round(float(np.mean([r["mean_speed_mps"] for r in rs])), 3),
                "max_speed_mps": round(float(max(r["max_speed_mps"] for r in rs)), 3),
                "occlusions": int(sum(r["occlusions"] for r in rs)),
            }
        )
    return out


def moving(row: dict) -> bool:
    """Whether a track row is reported in full: a person (whatever its mobility) or a dynamic track."""
    return row["class"] == CLASS_NAMES[CLASS_PERSON] or row["mobility"] == MOBILITY_NAMES[MOBILITY_DYNAMIC]


def static_rows(tracks: list[dict]) -> list[dict]:
    """The confirmed tracks that are neither people nor dynamic (static or undecided pieces of walls and
    furniture), summarised per (class, mobility): how many, their mean lifetime (s) and where their last
    confirmed positions are: bounding box and centroid (m, the report's frame)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in tracks:
        if r["confirmed"] and not moving(r):
            groups.setdefault((r["class"], r["mobility"]), []).append(r)
    order = {name: i for i, name in enumerate(CLASS_NAMES.values())}
    out = []
    static = MOBILITY_NAMES[MOBILITY_STATIC]
    for (cls, mob), rs in sorted(groups.items(), key=lambda kv: (order[kv[0][0]], kv[0][1] != static)):
        xy = np.array(
            [(r["x_m"], r["y_m"]) for r in rs if r["x_m"] is not None and r["y_m"] is not None], np.float64
        ).reshape(-1, 2)
        where = dict.fromkeys(("centroid_x_m", "centroid_y_m", "x_min_m", "x_max_m", "y_min_m", "y_max_m"))
        if len(xy):
            (cx, cy), (x0, y0), (x1, y1) = xy.mean(0), xy.min(0), xy.max(0)
            where = {k: round(float(v), 3) for k, v in zip(where, (cx, cy, x0, x1, y0, y1), strict=True)}
        out.append(
            {
                "class": cls,
                "mobility": mob,
                "tracks": len(rs),
                "mean_lifetime_s": round(float(np.mean([r["lifetime_s"] for r in rs])), 3),
                **where,
            }
        )
    return out


@dataclass
class RunSummary:
    """Everything `datmo report` prints about one run (see the module docstring for units and frames)."""

    run: dict
    features: dict | None
    landmarks: list[dict] | None
    classes: list[dict]
    tracks: list[dict]  # every track, confirmed or not
    frame: str  # "world" or "sensor": the frame of track positions and distances

    def confirmed(self) -> list[dict]:
        return [r for r in self.tracks if r["confirmed"]]

    def shown(self, top: int | None, sort: str, all_tracks: bool = False) -> list[dict]:
        """The tracks reported in full: the moving ones (every confirmed one with `all_tracks`), ordered by
        `sort`, the first `top` (all when None or 0)."""
        rows = sort_tracks([r for r in self.confirmed() if all_tracks or moving(r)], sort)
        return rows[:top] if top else rows

    def to_dict(self, top: int | None = None, sort: str = "lifetime") -> dict:
        """The file's entry of the JSON report: its file_row, then its details (see REPORT_SCHEMA)."""
        return {
            **self.file_row(),
            "run": self.run,
            "features": self.features,
            "landmark_list": self.landmarks,
            "frame": self.frame,
            "tentative_only": len(self.tracks) - len(self.confirmed()),
            "classes": self.classes,
            "moving_tracks": self.shown(top, sort),
            "static_by_class": static_rows(self.tracks),
        }

    def file_row(self) -> dict:
        """The file's row of the report (FILE_COLUMNS' keys, in order)."""
        conf = self.confirmed()
        f = self.features or {}
        row = {"file": self.run["file"], "duration_s": self.run["duration_s"], "scans": self.run["scans"]}
        for name in ("lines", "circles", "blobs"):
            row[f"{name}_per_scan"] = f[name]["per_scan"] if name in f else None
        row["landmarks"] = len(self.landmarks) if self.landmarks is not None else None
        row["tracks"] = len(conf)
        row["moving"] = sum(moving(r) for r in conf)
        row["static_pieces"] = len(conf) - row["moving"]
        for c in (CLASS_PERSON, CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN):
            row[CLASS_NAMES[c].replace(" ", "_")] = sum(r["class"] == CLASS_NAMES[c] for r in conf)
        row["dynamic"] = sum(r["mobility"] == MOBILITY_NAMES[MOBILITY_DYNAMIC] for r in conf)
        row["distance_m"] = round(sum(r["distance_m"] for r in conf), 3)
        return row


def sort_tracks(rows: list[dict], key: str) -> list[dict]:
    """Tracks ordered by `key` (one of SORT_KEYS): longest, farthest, fastest first; `first` and `id` ascending."""
    col = {
        "lifetime": "lifetime_s",
        "distance": "distance_m",
        "speed": "max_speed_mps",
        "first": "first_s",
        "id": "id",
    }[key]
    descending = key in ("lifetime", "distance", "speed")
    return sorted(rows, key=lambda r: ((-r[col] if descending else r[col]), r["id"]))
