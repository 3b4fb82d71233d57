"""A batch ready to run (`prepare`): the inputs found, the manifest read, and for each input whether it is
skipped (done before, unchanged) or redone, and whether its output may be overwritten."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from .. import __version__
from ..base.errors import DatmoError
from .discovery import discover
from .folder import out_folder
from .locations import exists, input_sha256, input_stat, local, remote
from .manifest import DONE, SKIPPED, Manifest
from .task import RunOptions, Task, params_hash

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@dataclass
class Batch:
    """A batch ready to run: its tasks, the manifest lines of the inputs it skips, and its ledger."""

    out_dir: str
    tasks: list[Task]
    skipped: list[dict]
    manifest: Manifest
    outputs: list[str] = field(default_factory=list)
    records: dict[str, dict] = field(default_factory=dict)  # input -> this batch's line

    @property
    def total(self) -> int:
        return len(self.tasks) + len(self.skipped)


def prepare(
    specs: list[str],
    out_dir: str,
    *,
    config: DatmoConfig | None = None,
    options: RunOptions | None = None,
    force: bool = False,
    command_line: str | None = None,
    threads: int | None = None,
) -> Batch:
    """Find the inputs, read the manifest and decide what to redo.

    An input is skipped when its latest manifest line is done (or skipped) by this datmo version with the
    same parameters' hash and the same input SHA-256 (not rehashed when size and mtime are unchanged) and
    its output exists with the size and SHA-256 the line recorded (rehashed only when its mtime moved); a
    line of another version is redone (outputs of two versions never mix silently); `force` redoes everything.
    An output that exists may be overwritten without `force` only when the
    manifest lists it for this input or it is the leftover of an interrupted batch (its provenance says
    `datmo run` of this input); any other existing output fails as its input with "use --force".
    Call it, and run_many, inside `folder_lock(out_dir)` (as `datmo run` does): two batches at once in one
    folder would each rewrite the other's manifest.
    """
    out_dir = out_folder(out_dir)
    options = options or RunOptions()
    pairs = discover(specs, out_dir, options.bag_dir)
    manifest = Manifest(out_dir)
    ledger = manifest.latest()
    phash = params_hash(config, options)
    tasks, skipped = [], []
    for i, (src, dst) in enumerate(pairs):
        last = ledger.get(src)
        owned = last is not None and last.get("output") == dst and last.get("status") in (DONE, SKIPPED)
        if (
            not force
            and owned
            and last is not None
            and last.get("params_hash") == phash
            and last.get("datmo_version") == __version__
            and exists(dst)
            and _same_input(src, last)
            and _same_output(dst, last)
        ):
            skipped.append(
                {**last, "status": SKIPPED, "error": None, "finished": datetime.now(UTC).isoformat(timespec="seconds")}
            )
            continue
        overwrite = force or (exists(dst) and (owned or _leftover(dst, src)))
        tasks.append(Task(i, src, dst, overwrite, config, options, phash, command_line, threads))
    if ledger:
        manifest.compact(ledger)  # one line per input before this batch appends its own
    return Batch(out_dir, tasks, skipped, manifest, [d for _, d in pairs])


def _same_input(src: str, last: dict) -> bool:
    from ..base.input_files import is_regular

    size, mtime = input_stat(src)
    if size is None or not (remote(src) or os.path.isdir(local(src)) or is_regular(local(src))):
        return False  # a FIFO or a device now: never hashed here (its task says what it is)
    if mtime is not None and size == last.get("input_size") and mtime == last.get("input_mtime_ns"):
        return True
    try:
        return input_sha256(src) == last.get("input_sha256")
    except OSError:
        return False


def _same_output(dst: str, last: dict) -> bool:
    """Whether output `dst` is still what the manifest line `last` recorded: its size, and its SHA-256 when
    its mtime moved (a line of a version that recorded neither: whether it exists)."""
    if last.get("output_size") is None and last.get("output_sha256") is None:
        return True
    size, mtime = input_stat(dst)
    if size is None or size != last.get("output_size"):
        return False  # truncated, grown or gone: redone
    if mtime is not None and mtime == last.get("output_mtime_ns"):
        return True
    try:
        return input_sha256(dst) == last.get("output_sha256")
    except OSError:
        return False


def _leftover(dst: str, src: str) -> bool:
    """True when `dst` is a datmo run output of `src` (a batch stopped before recording it)."""
    if remote(dst):
        return False
    from ..logs import mcapio

    try:
        meta = mcapio.summary(local(dst)).metadata
    except (DatmoError, OSError):
        return False
    return meta.get("datmo", {}).get("command") == "run" and src in meta.get("datmo.inputs", {})
