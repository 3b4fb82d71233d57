"""The rows of the exported tables, a block of decoded messages at a time (`Batch`): track states
(`track_batch`), features (`feature_batch`) and ground-truth targets (`ground_truth_batch`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..evaluate.frames import MOVER_CLASSES, target_mask
from ..logs import cdr, mcapio
from ..logs.vocabulary import BLOB_KIND_NAMES, CLASS_NAMES, MOBILITY_NAMES, STATUS_NAMES
from .schema import columns


@dataclass
class Batch:
    """Rows of one block of messages: `values[name]` (n,) for the columns these rows have; the output's other
    columns are empty. Float NaN is empty too."""

    n: int
    values: dict[str, np.ndarray]


def _constant(value: object, n: int) -> np.ndarray:
    out = np.empty(n, object)
    out[:] = [value] * n
    return out


def _names(codes: np.ndarray, names: dict[int, str], fallback: str) -> np.ndarray:
    table = np.array([names.get(c, fallback) for c in range(256)], object)  # codes are uint8
    return table[codes]


def decode_messages(path: Path, msgtype: str, topic: str, payloads: list[bytes], first: int) -> list[dict]:
    out = []
    for k, p in enumerate(payloads):
        try:
            out.append(cdr.decode(msgtype, p))
        except (ValueError, IndexError, TypeError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: bad {msgtype} message {first + k} on {topic} ({exc})") from None
    return out


def _per_message(file: str, first: int, decoded: list[dict], seq: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(elements of sequence `seq` of every message joined, the common columns of their rows)."""
    parts = [d[seq] for d in decoded]
    counts = np.array([len(p) for p in parts], np.int64)
    n = int(counts.sum())
    dtype = parts[0].dtype if parts else np.dtype(np.float32)
    items = np.frombuffer(b"".join(p.tobytes() for p in parts), dtype) if n else np.zeros(0, dtype)
    index = np.repeat(np.arange(len(decoded)), counts)
    common = {
        "file": _constant(file, n),
        "scan": (first + index).astype(np.int64),
        "stamp_ns": np.array([d["stamp_ns"] for d in decoded], np.int64)[index],
        "frame_id": np.array([d["frame_id"] for d in decoded], object)[index],
    }
    return items, common


def track_batch(file: str, first: int, decoded: list[dict]) -> Batch:
    """The rows of decoded Tracks messages (scans first, first + 1, ... of `file`): one per track state."""
    t, common = _per_message(file, first, decoded, "tracks")
    n = len(t)
    if not n:
        return Batch(0, {})
    values = {
        **common,
        "kind": _constant("track", n),
        "id": t["id"],
        "class": _names(t["classification"], CLASS_NAMES, "unknown"),
        "mobility": _names(t["mobility"], MOBILITY_NAMES, "undefined"),
        "status": _names(t["status"], STATUS_NAMES, "unknown"),
        "x_m": t["x"],
        "y_m": t["y"],
        "vx_mps": t["vx"],
        "vy_mps": t["vy"],
        "world_x_m": t["world_x"],
        "world_y_m": t["world_y"],
        "world_vx_mps": t["world_vx"],
        "world_vy_mps": t["world_vy"],
        "size_m": t["size"],
        "occluded": t["occluded"] != 0,
        "age": t["age"],
        "hits": t["hits"],
        "misses": t["misses"],
    }
    return Batch(n, values)


def _feature_part(file: str, first: int, decoded: list[dict], seq: str) -> Batch:
    f, common = _per_message(file, first, decoded, seq)
    n = len(f)
    if not n:
        return Batch(0, {})
    v = {**common, "segment": f["segment"], "first_beam": f["first"], "last_beam": f["last"], "n_points": f["n_points"]}
    if seq == "lines":
        v.update(
            kind=_constant("line", n),
            x_m=f["x_ini"],
            y_m=f["y_ini"],
            x_end_m=f["x_end"],
            y_end_m=f["y_end"],
            size_m=f["length"],
            rho_m=f["rho"],
            theta_rad=f["theta"],
            r_acc=f["r_acc"],
        )
    elif seq == "circles":
        v.update(kind=_constant("circle", n), x_m=f["x"], y_m=f["y"], radius_m=f["radius"], r_acc=f["r_acc"])
    elif seq == "blobs":
        kind = _names(f["kind"], BLOB_KIND_NAMES, "blob")
        v.update(kind=kind, x_m=f["x"], y_m=f["y"], size_m=f["size"])
    else:
        v.update(kind=_constant("leg", n), x_m=f["x"], y_m=f["y"], size_m=f["width"], probability=f["probability"])
    return Batch(n, v)


FEATURE_KINDS = ("lines", "circles", "blobs", "legs")


def feature_batch(file: str, first: int, decoded: list[dict]) -> Batch:
    """The rows of decoded Features messages: per message its lines, circles, blobs (and points), legs, each
    kind's rows in message order, the kinds in that order within the batch."""
    parts = [_feature_part(file, first, decoded, seq) for seq in FEATURE_KINDS if decoded and seq in decoded[0]]
    parts = [p for p in parts if p.n]
    if not parts:
        return Batch(0, {})
    names = [name for name in columns(True) if any(name in p.values for p in parts)]
    values = {}
    for name in names:
        kind = columns(True)[name]
        filled = []
        for p in parts:
            if name in p.values:
                filled.append(p.values[name])
            elif kind == "float32":
                filled.append(np.full(p.n, np.nan, np.float32))
            else:
                filled.append(_constant(None, p.n))
        values[name] = np.concatenate(
            [a.astype(object) if any(x.dtype == object for x in filled) else a for a in filled]
        )
    return Batch(sum(p.n for p in parts), values)


def ground_truth_batch(
    path: Path, first: int, decoded: list[dict], moved: np.ndarray, *, include_occluded: bool = False
) -> Batch:
    """The rows of decoded GroundTruth messages (messages first, first + 1, ... of the log at `path`): each
    message's targets in its order (`moved`: the run's moved_ids), or one row with only the stamp when it has
    none. A target position that is not finite is refused (InputError naming the message)."""
    parts = [d["objects"] for d in decoded]
    objects = np.concatenate(parts)
    frame = np.repeat(np.arange(len(decoded)), [len(o) for o in parts])
    keep = target_mask(objects, moved, include_occluded=include_occluded)
    t = objects[keep]
    bad = ~(np.isfinite(t["x"]) & np.isfinite(t["y"]))
    if bad.any():
        k = first + int(frame[keep][np.argmax(bad)])
        raise InputError(
            f"{path}: {mcapio.TOPIC_GROUND_TRUTH} message {k} holds a target position that is not a finite number"
        )
    empty = np.flatnonzero(np.bincount(frame[keep], minlength=len(decoded)) == 0)
    order = np.argsort(np.concatenate([frame[keep], empty]), kind="stable")  # each message's rows in place
    n = len(order)
    ids, cls = np.empty(n, object), np.empty(n, object)
    ids[: len(t)] = t["id"].tolist()
    cls[: len(t)] = [MOVER_CLASSES[c] for c in t["classification"].tolist()]
    x = np.concatenate([t["x"].astype(np.float64), np.full(len(empty), np.nan)])
    y = np.concatenate([t["y"].astype(np.float64), np.full(len(empty), np.nan)])
    stamps = np.array([d["stamp_ns"] for d in decoded], np.int64)[np.concatenate([frame[keep], empty])]
    return Batch(n, {"stamp_ns": stamps[order], "id": ids[order], "x": x[order], "y": y[order], "class": cls[order]})
