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

The modules: export.schema (the columns, their types and the output formats), export.rows (the rows of a
block of decoded messages), export.sinks (the CSV, NDJSON and Parquet writers) and export.passes (the passes
over the logs). The package re-exports their public names, so `from datmo_cli.export import X` keeps working.
"""

from .passes import BLOCK_MESSAGES, ROWS, Plan, export, export_ground_truth, plan, require_channel, row_batches
from .rows import FEATURE_KINDS, Batch, decode_messages, feature_batch, ground_truth_batch, track_batch
from .schema import (
    FEATURE_COLUMNS,
    FORMATS,
    GROUND_TRUTH_COLUMNS,
    SUFFIXES,
    TRACK_COLUMNS,
    TYPES,
    arrow_schema,
    columns,
    format_for,
    parquet_schema,
    polars_schema,
    require_pyarrow,
)
from .sinks import ParquetSink, TextSink, sink_for, to_stdout

__all__ = [
    "BLOCK_MESSAGES",
    "FEATURE_COLUMNS",
    "FEATURE_KINDS",
    "FORMATS",
    "GROUND_TRUTH_COLUMNS",
    "ROWS",
    "SUFFIXES",
    "TRACK_COLUMNS",
    "TYPES",
    "Batch",
    "ParquetSink",
    "Plan",
    "TextSink",
    "arrow_schema",
    "columns",
    "decode_messages",
    "export",
    "export_ground_truth",
    "feature_batch",
    "format_for",
    "ground_truth_batch",
    "plan",
    "parquet_schema",
    "polars_schema",
    "require_channel",
    "require_pyarrow",
    "row_batches",
    "sink_for",
    "to_stdout",
    "track_batch",
]
