"""Batches of `datmo run`: input discovery, output names, the manifest (the batch's ledger), resume, and
the one task every executor runs per input.

A batch turns INPUTS (files, folders searched recursively for .mcap logs, globs; local paths or fsspec
URLs) into one output per input under the output folder, and appends one JSON line per input to
OUT_DIR/manifest.jsonl as it finishes. Rerunning the same command skips the inputs whose latest line
says done with the same input SHA-256 and the same parameters' hash, and redoes the rest. The executor
(local processes here, Dask in `cluster.py`) only runs `run_task` on `Task`s and hands back records.

Paths: local inputs and outputs are absolute (the workers share the filesystem); `file://` URLs are
local paths; other fsspec URLs (`s3://...`) are staged through a local temporary folder on the worker.

The modules, in the order a batch uses them: locations (paths and URLs), discovery (the inputs), folder (the
output folder and its lock), manifest (the ledger, its statuses and figures), task (one input on a worker),
plan (prepare: what to redo), executors (local processes), running (run_many).
"""

from .discovery import LOG_SUFFIXES, discover
from .executors import Executor, LocalExecutor, die_with_parent
from .folder import LOCK, folder_lock, out_folder
from .locations import exists, input_sha256, input_stat, join, local, new_journal, remote, remove_recorded
from .manifest import (
    CANCELLED,
    DONE,
    FAILED,
    MANIFEST,
    RECORD_FIELDS,
    SKIPPED,
    SUMMARY_KEY,
    TRACK_CLASSES,
    Manifest,
    check_record,
    manifest_line,
    read_batch,
    summary,
)
from .plan import Batch, prepare
from .running import BatchInterrupted, run_many
from .task import Cancelled, RunOptions, Task, converted, failed, headline, params_hash, record, run_task

__all__ = [
    "CANCELLED",
    "DONE",
    "FAILED",
    "LOCK",
    "LOG_SUFFIXES",
    "MANIFEST",
    "RECORD_FIELDS",
    "SKIPPED",
    "SUMMARY_KEY",
    "TRACK_CLASSES",
    "Batch",
    "BatchInterrupted",
    "Cancelled",
    "Executor",
    "LocalExecutor",
    "Manifest",
    "RunOptions",
    "Task",
    "check_record",
    "converted",
    "die_with_parent",
    "discover",
    "exists",
    "failed",
    "folder_lock",
    "headline",
    "input_sha256",
    "input_stat",
    "join",
    "local",
    "new_journal",
    "manifest_line",
    "out_folder",
    "params_hash",
    "prepare",
    "read_batch",
    "record",
    "remote",
    "remove_recorded",
    "run_many",
    "run_task",
    "summary",
]
