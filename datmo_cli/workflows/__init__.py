"""The work of the commands, callable from Python (datmo_cli.api re-exports it):
each `datmo` command is its options, one call here (or to the module it names), and what it prints.

    batch_run   run_batch: `datmo run`'s batch (resume by the manifest, local or Dask executor, threads, plots,
                the report gathered as the outputs are written) and the kernels' warm-up before it
    reporting   report_files: `datmo report`'s summaries of processed logs and batch folders, and their plots
    recording   Recording: `datmo record`'s provenance, writer, driver and live view around lms2xx.recorder
    importing   import_log: `datmo import` (logs.importers, with the import's provenance)
    simulating  simulate: `datmo simulate` (a scene into a log with ground truth, or a ROS 1 bag)
    emulating   Emulation, emulate: `datmo emulate` (a virtual LMS200 on a pseudo-terminal, its link)
    playing     Player, play: `datmo play` (a log served to Foxglove, processed on the fly)
    ros_node    LiveNode, node: `datmo node` (a ROS 2 node over DDS, its warnings rate-limited)
    training    train_legs: `datmo train-legs` (the learned leg detector trained, its figures, the model)
    exporting   export_files: `datmo export` (tracks, features or ground truth as CSV, NDJSON, Parquet)
    inspecting  info, config: `datmo info` (what a log holds) and `datmo config` (the effective TOML)

No module here imports click: what a command prints reaches it through callbacks or progress (base).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from typing import TypeAlias

    from ..passes.config import DatmoConfig

    Config: TypeAlias = DatmoConfig | str | os.PathLike | dict | None


def as_config(config: Config) -> DatmoConfig:
    """A DatmoConfig from a DatmoConfig, a TOML file's path (its [features] and [track] tables, as --config),
    a dict of overrides ({"features": {...}, "track": {...}}), or None (the defaults)."""
    from ..passes.config import DatmoConfig, load

    if config is None or isinstance(config, DatmoConfig):
        return config or DatmoConfig()
    if isinstance(config, dict):
        return load(None, config)
    return load(Path(config))
