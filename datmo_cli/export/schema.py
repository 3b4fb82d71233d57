"""The exported tables' schema: their columns and types (TRACK_COLUMNS, FEATURE_COLUMNS, GROUND_TRUTH_COLUMNS),
as pyarrow and polars take them, and the format of an output (CSV, NDJSON or Parquet)."""

from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError
from ..extras import require

FORMATS = ("csv", "ndjson", "parquet")
SUFFIXES = {".csv": "csv", ".ndjson": "ndjson", ".jsonl": "ndjson", ".parquet": "parquet", ".pq": "parquet"}

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


def require_pyarrow():
    """pyarrow (with its parquet module loaded), or MissingExtraError naming the parquet extra."""
    require("pyarrow.parquet", for_="writing Parquet")
    return require("pyarrow", for_="writing Parquet")
