"""Per-scan tables out of processed logs: every track's state after every scan (and, optionally, every feature
of every scan), one row each, as CSV, NDJSON or Parquet, streamed in constant memory.

The schema is TRACK_COLUMNS (then, with --features, FEATURE_COLUMNS): the same columns, in this order, with
the same types in every format, whatever the number of logs, with or without odometry, and for a log with no
track or feature at all (CSV: the header line alone; NDJSON: an empty file; Parquet: the typed schema and no
row). docs/export.md documents every column (type, unit, frame, when it is null) and how to read each format
with its types (pyarrow, polars, pandas); `arrow_schema` and `polars_schema` give the schema to their readers.
Missing values are empty in CSV and null in NDJSON and Parquet (NaN world coordinates, any non-finite float
included). Floats are written as the shortest text that reads back to the same float32 (CSV, NDJSON) or as
float32 (Parquet). A CSV text field that a spreadsheet would run as a formula is written with a leading
apostrophe (csvsafe.neutralise). Rows come in this order: the track states of every file (files in the order
given, each file's in its order), then with --features the features of every file likewise.

With --ground-truth the table is instead one log's /datmo/ground_truth (datmo simulate) in the shape
`datmo evaluate --gt` reads, holding exactly the targets evaluate scores from the channel:

    stamp_ns      header stamp of the GroundTruth message (the scan's), ns since 1970
    id            the object's id (empty on a row that only marks a scan with no target)
    x, y          the object's centre, sensor frame, m (the float32 of the message, written exactly)
    class         person, circle object or rectangular object

Targets (evaluate.target_mask): objects of a mover class that move at some time in the run, in the scans
where a beam hits them (with `include_occluded`, in every scan). A message with no target gives one row with
only its stamp, so that evaluate counts the scan as a frame. What the CSV cannot carry: the channel's other
objects (scene structure, movers that never move, hidden targets), which evaluate uses as don't-care
regions; scored against the CSV, a confirmed track on one of them is a false positive, and may take a match
from a target, and a class whose only tracks lie on them gets a row of its own (no targets, all false
positives). On the simulated sample logs every other figure is the same (frames, objects, matches, misses,
switches, MOTP, LocA, recall, mostly tracked/lost), and false positives grow by exactly the channel's
ignored_hypotheses; MOTA, IDF1, precision, HOTA and DetA fall accordingly.

Streaming: each file is read twice, a summary pass (its channels and message counts: the progress bar's
total, and an input without /datmo/tracks refused before anything is written) and one pass per exported
channel with mcapio.iter_messages, one chunk in memory at a time, decoded and written `block` messages at a
time (a CSV or NDJSON batch of lines, a Parquet row group). The ground truth is read twice as well after
its summary: once for the ids that move (a whole-run fact; only the ids are kept), once for the rows.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np

from .csvsafe import neutralise
from .errors import ConfigError, InputError, MissingChannelError
from .evaluate import MOVER_CLASSES, moved_ids, target_mask
from .extras import require
from .log import cdr, mcapio, types
from .log.vocabulary import BLOB_KIND_NAMES, CLASS_NAMES, MOBILITY_NAMES, STATUS_NAMES

FORMATS = ("csv", "ndjson", "parquet")
SUFFIXES = {".csv": "csv", ".ndjson": "ndjson", ".jsonl": "ndjson", ".parquet": "parquet", ".pq": "parquet"}
BLOCK_MESSAGES = 1000  # messages decoded and written at once (one batch, one Parquet row group)

# The schema: column name -> type, in order (docs/export.md documents each column with its unit and frame).
# Types: string, int64, uint32, float32, float64, bool; every column may be null (empty in CSV).
TYPES = ("string", "int64", "uint32", "float32", "float64", "bool")
TRACK_COLUMNS: dict[str, str] = {
    "file": "string",
    "scan": "int64",
    "stamp_ns": "int64",
    "frame_id": "string",
    "kind": "string",
    "id": "uint32",
    "class": "string",
    "mobility": "string",
    "status": "string",
    "x_m": "float32",
    "y_m": "float32",
    "vx_mps": "float32",
    "vy_mps": "float32",
    "world_x_m": "float32",
    "world_y_m": "float32",
    "world_vx_mps": "float32",
    "world_vy_mps": "float32",
    "size_m": "float32",
    "occluded": "bool",
    "age": "uint32",
    "hits": "uint32",
    "misses": "uint32",
}
FEATURE_COLUMNS: dict[str, str] = {
    "segment": "uint32",
    "first_beam": "uint32",
    "last_beam": "uint32",
    "n_points": "uint32",
    "x_end_m": "float32",
    "y_end_m": "float32",
    "radius_m": "float32",
    "rho_m": "float32",
    "theta_rad": "float32",
    "r_acc": "float32",
    "probability": "float32",
}

GROUND_TRUTH_COLUMNS: dict[str, str] = {
    "stamp_ns": "int64",
    "id": "uint32",
    "x": "float64",
    "y": "float64",
    "class": "string",
}


def columns(features: bool = False) -> dict[str, str]:
    """The output's columns (name -> type, one of TYPES) in order: the track columns, then with `features` the
    feature columns."""
    return {**TRACK_COLUMNS, **(FEATURE_COLUMNS if features else {})}


def arrow_schema(cols: dict[str, str] | None = None, *, features: bool = False):
    """The pyarrow.Schema of a table of `cols` (default: columns(features)), as Parquet files carry it and as
    pyarrow's CSV and JSON readers take it (column_types, explicit_schema). Needs pyarrow (the parquet extra)."""
    pa = require_pyarrow()
    types_ = {
        "string": pa.string(),
        "int64": pa.int64(),
        "uint32": pa.uint32(),
        "float32": pa.float32(),
        "float64": pa.float64(),
        "bool": pa.bool_(),
    }
    return pa.schema([(name, types_[t]) for name, t in (cols or columns(features)).items()])


def polars_schema(cols: dict[str, str] | None = None, *, features: bool = False) -> dict:
    """{column: polars data type} of a table of `cols` (default: columns(features)), for polars' readers
    (`schema=`): CSV and NDJSON carry no types, and polars infers them from the first rows only. Needs polars."""
    import polars as pl

    types_ = {
        "string": pl.String,
        "int64": pl.Int64,
        "uint32": pl.UInt32,
        "float32": pl.Float32,
        "float64": pl.Float64,
        "bool": pl.Boolean,
    }
    return {name: types_[t] for name, t in (cols or columns(features)).items()}


def format_for(output: Path, fmt: str | None) -> str:
    """The format to write: `fmt` when given, else from OUT's suffix (.csv, .ndjson or .jsonl, .parquet or
    .pq), else csv for stdout ('-'); ConfigError naming -o for any other output."""
    if fmt is not None:
        return fmt
    if str(output) == "-":
        return "csv"
    found = SUFFIXES.get(output.suffix.lower())
    if found is None:
        raise ConfigError(
            f"{output}: cannot tell the format from the suffix {output.suffix or '(none)'!r}; name it "
            f"{', '.join(SUFFIXES)} or give --format {'/'.join(FORMATS)}"
        )
    return found


# -------------------------------------------------------------------------------------------- batches


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


def _decode(path: Path, msgtype: str, topic: str, payloads: list[bytes], first: int) -> list[dict]:
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


# ---------------------------------------------------------------------------------------------- sinks


def _text_column(kind: str, a: np.ndarray, null: str, quote: bool) -> list[str]:
    """A column's values as text: float32 as its shortest round-trip form, non-finite floats and None as `null`;
    strings JSON-quoted with `quote`, else as CSV fields."""
    if kind in ("float32", "float64") and a.dtype != object:
        out = a.astype(np.float32 if kind == "float32" else np.float64).astype(str).astype(object)
        out[~np.isfinite(a)] = null
        return out.tolist()
    if kind == "bool" and a.dtype != object:
        return np.where(a, "true", "false").tolist()
    if a.dtype != object:
        return list(map(str, a.tolist()))

    def text(v: object) -> str:
        if v is None:
            return null
        if kind == "string":
            return json.dumps(v) if quote else _csv_field(neutralise(v))
        if kind == "bool":
            return "true" if v else "false"
        return str(v)

    values = a.tolist()
    texts = {v: text(v) for v in set(values)}  # few distinct values: file names, classes, kinds
    return list(map(texts.__getitem__, values))


def _csv_field(text: str) -> str:
    """`text` as a CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _text_columns(cols: dict[str, str], batch: Batch, null: str, quote: bool) -> list[list[str]]:
    return [
        _text_column(kind, batch.values[name], null, quote) if name in batch.values else [null] * batch.n
        for name, kind in cols.items()
    ]


class TextSink:
    """CSV or NDJSON rows to a binary stream, one write per batch. Strings in UTF-8 (file names that are not
    are written as their bytes in CSV, \\uXXXX-escaped in NDJSON)."""

    def __init__(self, stream: IO[bytes], fmt: str, cols: dict[str, str]) -> None:
        self.stream, self.fmt, self.cols = stream, fmt, cols
        self.rows = self.batches = self.peak_rows = 0
        keys = ",".join(f"{json.dumps(name)}:%s" for name in cols)
        self._template = "{" + keys + "}\n"
        if fmt == "csv":
            self._write(",".join(_csv_field(name) for name in cols) + "\n")

    def _write(self, text: str) -> None:
        self.stream.write(text.encode("utf-8", "surrogateescape"))

    def write(self, batch: Batch) -> None:
        if not batch.n:
            return
        if self.fmt == "csv":
            self._write(
                "".join(",".join(row) + "\n" for row in zip(*_text_columns(self.cols, batch, "", False), strict=True))
            )
        else:
            template = self._template
            self._write(
                "".join(template % row for row in zip(*_text_columns(self.cols, batch, "null", True), strict=True))
            )
        self.rows += batch.n
        self.batches += 1
        self.peak_rows = max(self.peak_rows, batch.n)

    def close(self) -> None:
        self.stream.flush()


def require_pyarrow():
    """pyarrow (with its parquet module loaded), or MissingExtraError naming the parquet extra."""
    require("pyarrow.parquet", for_="writing Parquet")
    return require("pyarrow", for_="writing Parquet")


class ParquetSink:
    """Rows to a Parquet file (pyarrow.parquet.ParquetWriter), one row group per batch, zstd-compressed."""

    def __init__(self, stream: IO[bytes], cols: dict[str, str]) -> None:
        self.pa = require_pyarrow()
        self.cols = cols
        self.schema = arrow_schema(cols)
        import pyarrow.parquet as pq

        self.writer = pq.ParquetWriter(stream, self.schema, compression="zstd")
        self.rows = self.batches = self.peak_rows = 0

    def _array(self, name: str, a: np.ndarray | None, n: int):
        pa, typ = self.pa, self.schema.field(name).type
        if a is None:
            return pa.nulls(n, typ)
        if a.dtype == object:
            values = [None if v is None or (isinstance(v, float) and np.isnan(v)) else v for v in a.tolist()]
            if pa.types.is_string(typ):
                values = [
                    v if v is None else v.encode("utf-8", "surrogateescape").decode("utf-8", "replace") for v in values
                ]
            return pa.array(values, typ)
        if pa.types.is_floating(typ):
            return pa.array(a.astype(np.float64 if pa.types.is_float64(typ) else np.float32), typ, mask=np.isnan(a))
        return pa.array(a, typ)

    def write(self, batch: Batch) -> None:
        if not batch.n:
            return
        arrays = [self._array(name, batch.values.get(name), batch.n) for name in self.cols]
        self.writer.write_table(self.pa.Table.from_arrays(arrays, schema=self.schema), row_group_size=batch.n)
        self.rows += batch.n
        self.batches += 1
        self.peak_rows = max(self.peak_rows, batch.n)

    def close(self) -> None:
        self.writer.close()


def sink_for(
    stream: IO[bytes], fmt: str, features: bool = False, cols: dict[str, str] | None = None
) -> TextSink | ParquetSink:
    """The writer of `fmt` rows to the binary `stream`: of `cols` when given (GROUND_TRUTH_COLUMNS), else of
    columns(features)."""
    cols = cols or columns(features)
    return ParquetSink(stream, cols) if fmt == "parquet" else TextSink(stream, fmt, cols)


# ----------------------------------------------------------------------------------------------- export


@dataclass
class Plan:
    """What the summary pass of each input found: its path and its message counts per exported topic."""

    files: list[Path]
    counts: list[dict[str, int]] = field(default_factory=list)

    def total(self, topic: str) -> int:
        return sum(c.get(topic, 0) for c in self.counts)


def require_channel(log: mcapio.LogContents, topic: str, msgtype: str) -> int:
    """The number of `msgtype` messages on `topic` of `log`; MissingChannelError naming the command that writes
    them when there are none, InputError when the channel holds another type."""
    ch = log.topics().get(topic)
    if ch is None or not ch.count:
        if topic == mcapio.TOPIC_GROUND_TRUTH:
            raise MissingChannelError(
                f"{log.path}: no messages on {topic}; only {mcapio.PRODUCER[topic]} writes "
                "ground truth (annotate a real log as a stamp_ns,id,x,y CSV instead)"
            )
        raise MissingChannelError(f"{log.path}: no messages on {topic}; run {mcapio.PRODUCER[topic]} first")
    if ch.msgtype != msgtype or ch.message_encoding != "cdr":
        raise InputError(f"{log.path}: {topic} holds {ch.message_encoding} {ch.msgtype}, not CDR {msgtype}")
    return ch.count


def plan(files: list[Path], features: bool = False, ground_truth: bool = False) -> Plan:
    """Summary pass over every input (mcapio.summary): refuses, before anything is written, an input that is
    not a log or has no /datmo/tracks (or, with `features`, no /datmo/features; with `ground_truth` only
    /datmo/ground_truth is needed), naming the command to run."""
    out = Plan(list(files))
    for path in files:
        log = mcapio.summary(path)
        if ground_truth:
            out.counts.append(
                {mcapio.TOPIC_GROUND_TRUTH: require_channel(log, mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH)}
            )
            continue
        counts = {mcapio.TOPIC_TRACKS: require_channel(log, mcapio.TOPIC_TRACKS, types.TRACKS)}
        if features:
            counts[mcapio.TOPIC_FEATURES] = require_channel(log, mcapio.TOPIC_FEATURES, types.FEATURES)
        out.counts.append(counts)
    return out


def _batches(path: Path, topic: str, block: int) -> Iterator[tuple[int, list[bytes]]]:
    """(index of the first, payloads) of each block of `block` messages on `topic` of the log at `path`."""
    pending: list[bytes] = []
    first = 0
    for _, _, payload in mcapio.iter_messages(path, [topic], warn=False):
        pending.append(payload)
        if len(pending) == block:
            yield first, pending
            first += len(pending)
            pending = []
    if pending:
        yield first, pending


ROWS = {mcapio.TOPIC_TRACKS: (types.TRACKS, track_batch), mcapio.TOPIC_FEATURES: (types.FEATURES, feature_batch)}


def row_batches(
    path: Path, topic: str, name: str | None = None, block: int = BLOCK_MESSAGES
) -> Iterator[tuple[int, Batch]]:
    """(messages read, their rows) for each block of `block` messages on `topic` (/datmo/tracks or
    /datmo/features, a key of ROWS) of the log at `path`; `name` fills the file column (default: the path)."""
    msgtype, rows = ROWS[topic]
    name = os.fsdecode(path) if name is None else name
    for first, payloads in _batches(path, topic, block):
        yield len(payloads), rows(name, first, _decode(path, msgtype, topic, payloads, first))


def export(
    p: Plan,
    sink: TextSink | ParquetSink,
    *,
    features: bool = False,
    block: int = BLOCK_MESSAGES,
    progress: Callable[[str, int], None] | None = None,
) -> None:
    """Write the rows of every input of `p` to `sink`, `block` messages at a time: every file's track states,
    then (with `features`) every file's features. `progress(topic, n)` after each block of n messages of
    `topic`."""
    for topic in [mcapio.TOPIC_TRACKS] + ([mcapio.TOPIC_FEATURES] if features else []):
        for path in p.files:
            for n, batch in row_batches(path, topic, block=block):
                sink.write(batch)
                if progress is not None:
                    progress(topic, n)


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


def export_ground_truth(
    path: Path,
    sink: TextSink | ParquetSink,
    *,
    include_occluded: bool = False,
    block: int = BLOCK_MESSAGES,
    progress: Callable[[str, int], None] | None = None,
) -> None:
    """Write the targets of the /datmo/ground_truth channel of the log at `path` to `sink` (of
    GROUND_TRUTH_COLUMNS), `block` messages at a time, in two passes: `progress("movers", n)` after each
    block of the pass that finds the ids that move (and checks that the stamps increase: InputError naming the
    first message that does not), `progress("targets", n)` after each block written."""
    topic, msgtype = mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH
    moved = np.zeros(0, np.int64)
    last = None
    for first, payloads in _batches(path, topic, block):
        decoded = _decode(path, msgtype, topic, payloads, first)
        moved = np.union1d(moved, moved_ids(np.concatenate([d["objects"] for d in decoded])))
        stamps = np.array(([] if last is None else [last]) + [d["stamp_ns"] for d in decoded], np.int64)
        back = np.flatnonzero(np.diff(stamps) <= 0)
        if len(back):  # a frame per stamp: evaluate --gt would read two messages of one stamp as one frame
            k = first + int(back[0]) - (last is not None) + 1
            raise InputError(
                f"{path}: {topic} message {k} has stamp_ns {int(stamps[back[0] + 1])}, not after the "
                f"previous message's {int(stamps[back[0]])}"
            )
        last = int(stamps[-1])
        if progress is not None:
            progress("movers", len(payloads))
    for first, payloads in _batches(path, topic, block):
        decoded = _decode(path, msgtype, topic, payloads, first)
        sink.write(ground_truth_batch(path, first, decoded, moved, include_occluded=include_occluded))
        if progress is not None:
            progress("targets", len(payloads))


def to_stdout(fmt: str) -> IO[bytes]:
    """stdout's binary stream for CSV or NDJSON rows; Parquet (binary, written at the end) is refused."""
    if fmt == "parquet":
        raise ConfigError("-o -: Parquet is not written to stdout; give a file name (or --format csv or ndjson)")
    return sys.stdout.buffer
