"""The exported tables' schema: their columns and types (TRACK_COLUMNS, FEATURE_COLUMNS, GROUND_TRUTH_COLUMNS),
as pyarrow and polars take them, and the format of an output (CSV, NDJSON or Parquet)."""

from __future__ import annotations

from pathlib import Path

from ..base.errors import ConfigError
from ..base.extras import require

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


# Each column's unit (and frame) as docs/export.md gives it, carried in a Parquet file's metadata; "" for none.
UNITS: dict[str, str] = {
    "stamp_ns": "ns since 1970 (UTC)",
    "stamp": "ns since 1970, UTC (timestamp of stamp_ns)",
    **{c: "m, sensor frame" for c in ("x_m", "y_m", "x_end_m", "y_end_m")},
    **{c: "m/s, sensor frame" for c in ("vx_mps", "vy_mps")},
    **{c: "m, odometry frame" for c in ("world_x_m", "world_y_m")},
    **{c: "m/s, odometry frame" for c in ("world_vx_mps", "world_vy_mps")},
    **{c: "m" for c in ("size_m", "radius_m", "rho_m")},
    "theta_rad": "rad",
    **{c: "scans" for c in ("age", "hits", "misses")},
    **{c: "beam index" for c in ("first_beam", "last_beam")},
    "probability": "0 to 1",
}
UNITS.update({"x": "m, sensor frame", "y": "m, sensor frame"})  # GROUND_TRUTH_COLUMNS' own
STAMP = "stamp"  # the Parquet column beside stamp_ns: the same instant as a timestamp (ns, UTC)


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


def parquet_schema(cols: dict[str, str]):
    """The pyarrow.Schema a Parquet export is written with: arrow_schema(cols) with, after `stamp_ns`, the column
    `stamp` (the same instant as timestamp[ns, UTC], which polars, duckdb and pandas read as a time); each field's
    unit in its metadata ("unit"), and the table's columns, types and units as JSON under b"datmo" in the
    schema's metadata (units from UNITS)."""
    import json

    pa = require_pyarrow()
    base = arrow_schema(cols)
    units = UNITS
    fields = []
    for f in base:
        fields.append(f.with_metadata({"unit": units.get(f.name, "")}) if units.get(f.name) else f)
        if f.name == "stamp_ns":
            fields.append(pa.field(STAMP, pa.timestamp("ns", tz="UTC"), metadata={"unit": units[STAMP]}))
    described = {
        f.name: {"type": cols.get(f.name, "timestamp[ns, UTC]"), "unit": units.get(f.name, "")} for f in fields
    }
    meta = {"columns": described, "docs": "docs/export.md (in the datmo-cli source distribution)"}
    return pa.schema(fields, metadata={b"datmo": json.dumps(meta).encode()})


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
