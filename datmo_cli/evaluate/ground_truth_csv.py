"""Ground truth read from a CSV file (annotated real logs): `stamp_ns,id,x,y[,class]` rows, sensor frame, m,
each checked, into Frames of targets (no don't-care regions)."""

from __future__ import annotations

import csv
import io

import numpy as np

from ..base.errors import InputError
from ..logs.vocabulary import CLASS_PERSON
from .frames import MOVER_CLASSES, Frames

# a ground-truth CSV's class: the name, with underscores or its first word ("circle"), or "people"
CLASS_BY_NAME = {
    "people": CLASS_PERSON,
    **{
        alias: code for code, name in MOVER_CLASSES.items() for alias in (name, name.replace(" ", "_"), name.split()[0])
    },
}


INT64_MAX = np.iinfo(np.int64).max


def read_ground_truth_csv(path, name: str | None = None) -> Frames:
    """Ground truth from a CSV file (see parse_ground_truth_csv): UTF-8 text, a leading byte-order mark
    allowed (spreadsheets write one). A binary file, text that is not UTF-8, or a file that cannot be read
    raises InputError naming it."""
    from ..base.input_files import MAX_GROUND_TRUTH_BYTES, read_bytes

    name = name or str(path)
    data = read_bytes(path, MAX_GROUND_TRUTH_BYTES, "ground-truth CSV file", name=name)
    if b"\x00" in data:
        raise InputError(f"{name}: binary data (a NUL byte at byte {data.index(0)}), not a CSV text file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{name}: not UTF-8 text (byte {exc.start}), not a CSV text file") from None
    return parse_ground_truth_csv(text, name)


def parse_ground_truth_csv(text: str, name: str = "ground truth") -> Frames:
    """Ground truth from CSV text with a header `stamp_ns,id,x,y` (sensor frame, m) and an optional
    `class` column (person, circle, rectangular or 1-3; empty: unknown). A row with an empty id marks an
    annotated scan with no objects in it. Frames are the distinct stamps, in ascending order.

    Refused with InputError naming the line: a stamp that is not an integer of int64 nanoseconds, an id
    that is not an integer, a position that is not a finite number, a class that is none of those, and an
    id twice at one stamp (one object cannot be in two places at once)."""
    text = text.removeprefix("\ufeff")
    try:
        reader = csv.DictReader(io.StringIO(text))
        cols = {c.strip().lower(): c for c in reader.fieldnames or [] if c is not None}
        missing = [c for c in ("stamp_ns", "id", "x", "y") if c not in cols]
        if missing:
            raise InputError(f"{name}: CSV needs the columns stamp_ns,id,x,y; missing {','.join(missing)}")
        rows = _csv_rows(reader, cols, name)
    except csv.Error as exc:
        raise InputError(f"{name}: line {reader.line_num}: not CSV ({exc})") from None
    stamps, ids, xs, ys, cls, empty = rows
    if not stamps and not empty:
        raise InputError(f"{name}: no ground-truth rows")
    st = np.array(stamps, np.int64)
    order = np.argsort(st, kind="stable")
    frames = np.unique(np.concatenate([st, np.array(empty, np.int64)]))
    offsets = np.searchsorted(st[order], frames, side="left")
    offsets = np.append(offsets, len(st)).astype(np.int64)
    return Frames(
        frames,
        offsets,
        np.array(ids, np.int64)[order],
        np.array(xs)[order],
        np.array(ys)[order],
        np.array(cls, np.int64)[order],
    )


def _csv_rows(reader: csv.DictReader, cols: dict[str, str], name: str) -> tuple[list, ...]:
    """(stamps, ids, xs, ys, classes, stamps of empty rows) of the CSV's rows, each checked."""
    stamps, ids, xs, ys, cls, empty = [], [], [], [], [], []
    seen: dict[tuple[int, int], int] = {}  # (stamp, id) -> line
    for row in reader:
        line = reader.line_num
        cell = _cells(row, cols)
        stamp = _integer(cell("stamp_ns"), "stamp_ns", name, line)
        if not 0 <= stamp <= INT64_MAX:
            raise InputError(f"{name}: line {line}: stamp_ns {stamp} is outside int64 nanoseconds (0 to {INT64_MAX})")
        raw_id = cell("id")
        if not raw_id:
            empty.append(stamp)
            continue
        ident = _integer(raw_id, "id", name, line)
        if not -INT64_MAX <= ident <= INT64_MAX:
            raise InputError(f"{name}: line {line}: id {ident} is outside int64")
        x, y = (_finite(cell(c), c, name, line) for c in ("x", "y"))
        c = cell("class").lower()
        code = int(c) if c.isascii() and c.isdigit() else CLASS_BY_NAME.get(c, -1) if c else 0
        if code not in MOVER_CLASSES and c:
            raise InputError(f"{name}: line {line}: unknown class {c!r} (person, circle, rectangular, 1-3 or empty)")
        if (stamp, ident) in seen:
            raise InputError(
                f"{name}: line {line}: id {ident} again at stamp_ns {stamp} (first at line "
                f"{seen[stamp, ident]}); one object per id and frame"
            )
        seen[stamp, ident] = line
        stamps.append(stamp)
        ids.append(ident)
        xs.append(x)
        ys.append(y)
        cls.append(code)
    return stamps, ids, xs, ys, cls, empty


def _cells(row: dict, cols: dict[str, str]):
    return lambda col: (row.get(cols[col]) or "").strip() if col in cols else ""


def _integer(text: str, col: str, name: str, line: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(f"{name}: line {line}: {col} {text!r} is not an integer") from None


def _finite(text: str, col: str, name: str, line: int) -> float:
    """A position cell, metres: a finite number."""
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{name}: line {line}: {col} {text!r} is not a number") from None
    if not np.isfinite(v):
        raise InputError(f"{name}: line {line}: {col} is {text}; positions must be finite (metres)")
    return v
