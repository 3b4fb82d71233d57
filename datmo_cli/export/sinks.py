"""Writers of the exported rows to a binary stream: CSV and NDJSON text (`TextSink`), Parquet (`ParquetSink`)."""

from __future__ import annotations

import json
import sys
from typing import IO

import numpy as np

from ..base.csvsafe import neutralise
from ..base.errors import ConfigError
from ..base.text import printable
from .rows import Batch
from .schema import columns, parquet_schema, require_pyarrow


def _text_column(kind: str, a: np.ndarray, null: str, quote: bool, terminal: bool = False) -> list[str]:
    """A column's values as text: float32 as its shortest round-trip form, non-finite floats and None as `null`;
    strings JSON-quoted with `quote`, else as CSV fields (with `terminal`, their control characters escaped
    first: text.printable)."""
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
            if quote:
                return json.dumps(v)
            return _csv_field(neutralise(printable(v) if terminal else str(v)))
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


def _text_columns(
    cols: dict[str, str], batch: Batch, null: str, quote: bool, terminal: bool = False
) -> list[list[str]]:
    return [
        _text_column(kind, batch.values[name], null, quote, terminal) if name in batch.values else [null] * batch.n
        for name, kind in cols.items()
    ]


class TextSink:
    """CSV or NDJSON rows to a binary stream, one write per batch. Strings in UTF-8 (file names that are not
    are written as their bytes in CSV, \\uXXXX-escaped in NDJSON). With `terminal` (stdout is a terminal) the
    CSV's text fields have their control characters escaped (text.printable: a log's frame id must not clear
    the screen or open a link); NDJSON's strings are escaped by JSON anyway."""

    def __init__(self, stream: IO[bytes], fmt: str, cols: dict[str, str], terminal: bool = False) -> None:
        self.stream, self.fmt, self.cols, self.terminal = stream, fmt, cols, terminal
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
                "".join(
                    ",".join(row) + "\n"
                    for row in zip(*_text_columns(self.cols, batch, "", False, self.terminal), strict=True)
                )
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

    def abort(self) -> None:
        """Nothing to undo after an error (the output file is removed by its writer)."""


class ParquetSink:
    """Rows to a Parquet file (pyarrow.parquet.ParquetWriter), one row group per batch, zstd-compressed, with
    schema.parquet_schema's `stamp` column beside `stamp_ns` and the columns' units in the metadata."""

    def __init__(self, stream: IO[bytes], cols: dict[str, str]) -> None:
        self.pa = require_pyarrow()
        self.cols = cols
        self.schema = parquet_schema(cols)
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
        arrays = []
        for name in self.cols:
            arrays.append(self._array(name, batch.values.get(name), batch.n))
            if name == "stamp_ns":
                arrays.append(arrays[-1].cast(self.pa.timestamp("ns", tz="UTC")))
        self.writer.write_table(self.pa.Table.from_arrays(arrays, schema=self.schema), row_group_size=batch.n)
        self.rows += batch.n
        self.batches += 1
        self.peak_rows = max(self.peak_rows, batch.n)

    def close(self) -> None:
        self.writer.close()

    def abort(self) -> None:
        """Close the writer after an error or Ctrl-C, while its file is still open (the file is then removed):
        else pyarrow closes it when the writer is collected, after the file is closed, and prints "Exception
        ignored in ParquetWriter.__del__" after datmo's one-line error."""
        try:
            self.writer.close()
        except Exception:
            pass


def sink_for(
    stream: IO[bytes], fmt: str, features: bool = False, cols: dict[str, str] | None = None, terminal: bool = False
) -> TextSink | ParquetSink:
    """The writer of `fmt` rows to the binary `stream`: of `cols` when given (GROUND_TRUTH_COLUMNS), else of
    columns(features); `terminal`: the stream is a terminal (TextSink)."""
    cols = cols or columns(features)
    return ParquetSink(stream, cols) if fmt == "parquet" else TextSink(stream, fmt, cols, terminal)


def to_stdout(fmt: str) -> IO[bytes]:
    """stdout's binary stream for CSV or NDJSON rows; Parquet (binary, written at the end) is refused."""
    if fmt == "parquet":
        raise ConfigError("-o -: Parquet is not written to stdout; give a file name (or --format csv or ndjson)")
    return sys.stdout.buffer
