"""The per-run report: what a processed log saw, summarised from its decoded channels, and its formats.

A RunAccumulator (report.accumulate) gathers the report from decoded messages fed block by block (O(1) numbers
per track, per distinct scan period and per feature kind; nothing per scan), then gives a RunSummary of plain
dicts (report.summary). `summarise_file` (and `stream_run`, report.stream) walk a log once, BLOCK_MESSAGES
messages at a time, so the report of a log of any length fits in bounded memory: the one place here that reads
a file. `RunData.from_log` (report.decode) decodes an already-read log whole (for the plot and evaluate) and
`summarise` feeds it to the same accumulator, so both give the same summary. report.tables lays summaries out
as tables and shapes (REPORT_SCHEMA); report.formats prints them (`render`: rich, markdown, CSV, JSON). Times
in the report are seconds from the first scan; positions and distances in metres, in the world (odometry)
frame when every track state has finite world coordinates, else in the sensor frame; speeds in m/s.

The package re-exports the public names of its modules, so `from datmo_cli.report import X` keeps working.
"""

from .accumulate import FEATURE_KINDS, RunAccumulator, ScanStats, summarise
from .decode import Decoded, RunData, decode_channel, require
from .formats import (
    FORMATS,
    console,
    render,
    render_csv,
    render_markdown,
    render_rich,
    report_dict,
    to_json,
    track_rows,
)
from .stream import BLOCK_MESSAGES, SUMMARY_TOPICS, stream_run, summarise_file
from .summary import SORT_KEYS, RunSummary, class_rows, moving, sort_tracks, static_rows
from .tables import (
    FILE_COLUMNS,
    LANDMARK_COLUMNS,
    PARAM_WIDTH,
    REPORT_SCHEMA,
    SCHEMA,
    STATIC_COLUMNS,
    TRACK_COLUMNS,
    TRACK_CSV_KEYS,
    Table,
    file_table,
    file_tables,
    param_text,
    total_row,
)
from .tracks import FRAMES, TrackHistory, TrackStats, track_history

__all__ = [
    "BLOCK_MESSAGES",
    "FEATURE_KINDS",
    "FILE_COLUMNS",
    "FORMATS",
    "FRAMES",
    "LANDMARK_COLUMNS",
    "PARAM_WIDTH",
    "REPORT_SCHEMA",
    "SCHEMA",
    "SORT_KEYS",
    "STATIC_COLUMNS",
    "SUMMARY_TOPICS",
    "TRACK_COLUMNS",
    "TRACK_CSV_KEYS",
    "Decoded",
    "RunAccumulator",
    "RunData",
    "RunSummary",
    "ScanStats",
    "Table",
    "TrackHistory",
    "TrackStats",
    "class_rows",
    "console",
    "decode_channel",
    "file_table",
    "file_tables",
    "moving",
    "param_text",
    "render",
    "render_csv",
    "render_markdown",
    "render_rich",
    "report_dict",
    "require",
    "sort_tracks",
    "static_rows",
    "stream_run",
    "summarise",
    "summarise_file",
    "to_json",
    "total_row",
    "track_history",
    "track_rows",
]
