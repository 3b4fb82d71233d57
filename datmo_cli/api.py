"""datmo for Python and notebooks (docs/python.md): open a processed log and get its tracks and features as
numpy arrays or pandas DataFrames, run the pipeline on a log, and feed scans one at a time to a tracker.

    open_log(path)          a Log: .tracks() and .features() as numpy structured arrays, .tracks_dataframe() and
                            .features_dataframe() as pandas DataFrames (the pandas extra), .read_scans() and
                            .poses() (the scans and the scanner's poses, to feed a LiveTracker)
    process(src, out)       `datmo run` on one MCAP log (segmentation, features, tracking), written to `out`
    run_batch(inputs, dir)  `datmo run`: a batch of inputs, resumed by its manifest, local or on Dask, with plots
                            and the report's summaries (workflows.batch_run)
    report(files)           `datmo report`: the summaries of processed logs and batch folders (workflows.reporting)
    evaluate(file)          `datmo evaluate`: CLEAR-MOT, identity and HOTA scores against ground truth
    record(port, out)       `datmo record`: a SICK LMS200 (or the emulator) into a log; Recording for more control
    LiveTracker(...)        .update(ranges, stamp_ns, pose=None): one scan in, the tracks after it out
    tune(logs, space, dir)  `datmo tune`: the setting of a space of parameters that scores best against ground truth

    segment, extract_features, track, warm_up: `datmo segment`, `features`, `track`, `warm-up` (stage_files, warm)
    import_log(src, out)    `datmo import`: a CARMEN log, g2o file, bag or MCAP into a datmo scan log (ImportResult)
    simulate(out, scene)    `datmo simulate`: a scene into a log with ground truth (SimulateResult)
    emulate(scene, log)     `datmo emulate`: an Emulation, a virtual LMS200 on a pseudo-terminal (`with`, .serve)
    play(log) / Player      `datmo play`: a log served to Foxglove (Player: the steps, to print between them)
    node(scan_topic)        `datmo node`: a LiveNode, a ROS 2 node over DDS (.spin(stop), .close())
    train_legs(pos, neg, out)  `datmo train-legs`: the learned leg detector trained and written (LegTraining)
    export(files, out)      `datmo export`: tracks, features or ground truth as CSV, NDJSON or Parquet
    info(log)               `datmo info --json`: the log's channels, scan geometry, rate and provenance (a dict)
    config(config, out)     `datmo config`: the effective configuration as TOML, with where each value came from

Each of these is what its command runs: the command is its options, this call, and what it prints.

The same code as the commands: `process` is pipeline.process_file (what `datmo run` runs per input), the tables
are `datmo export`'s rows (export.track_batch and feature_batch; the tracks table has export.TRACK_COLUMNS),
and LiveTracker runs pipeline.RunStages, the stages `datmo run`, `play` and `record --live` run, a block of one
scan at a time. Units and frames as everywhere in datmo: metres, radians, seconds, int64 ns stamps; x_m, y_m
and velocities in the scan's sensor frame (x forward, y left), world_* in the odometry frame.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from . import export as _export
from .base.errors import InputError
from .base.extras import require
from .logs import cdr, mcapio, types
from .workflows import as_config as _config
from .workflows.batch_run import BatchResult, run_batch
from .workflows.recording import Recording, record
from .workflows.reporting import ReportResult
from .workflows.reporting import report_files as report

if TYPE_CHECKING:
    import pandas

    from .logs.scan import ScanRun
    from .passes.stage_files import features_file as extract_features
    from .passes.stage_files import segment_file as segment
    from .passes.stage_files import track_file as track
    from .passes.warm import warm_up
    from .tune import run_tune as tune
    from .workflows import Config
    from .workflows.emulating import Emulation, emulate
    from .workflows.exporting import ExportResult
    from .workflows.exporting import export_files as export
    from .workflows.importing import ImportResult, import_log
    from .workflows.inspecting import config, info
    from .workflows.playing import Player, play
    from .workflows.ros_node import LiveNode, node
    from .workflows.simulating import SimulateResult, simulate
    from .workflows.training import LegTraining, train_legs

__all__ = [
    "FEATURE_COLUMNS",
    "TRACK_COLUMNS",
    "BatchResult",
    "Emulation",
    "ExportResult",
    "ImportResult",
    "LegTraining",
    "LiveNode",
    "LiveTracker",
    "Log",
    "Player",
    "Recording",
    "ReportResult",
    "SimulateResult",
    "config",
    "emulate",
    "evaluate",
    "export",
    "extract_features",
    "import_log",
    "info",
    "node",
    "open_log",
    "play",
    "process",
    "record",
    "report",
    "run_batch",
    "segment",
    "simulate",
    "track",
    "train_legs",
    "tune",
    "warm_up",
]

# The tables' columns (name -> type): the tracks table is the export's; the features table has the columns that
# describe features (the export's feature rows without the track-only columns, which are null there).
TRACK_COLUMNS: dict[str, str] = dict(_export.TRACK_COLUMNS)
FEATURE_COLUMNS: dict[str, str] = {
    name: _export.TRACK_COLUMNS[name]
    for name in ("file", "scan", "stamp_ns", "frame_id", "kind", "x_m", "y_m", "size_m")
} | _export.FEATURE_COLUMNS
_NUMPY = {
    "string": object,
    "int64": np.int64,
    "uint32": np.uint32,
    "float32": np.float32,
    "float64": np.float64,
    "bool": np.bool_,
}


# the other commands' work, imported on first use: name -> (module under datmo_cli, function)
_LAZY = {
    "tune": ("tune", "run_tune"),  # datmo tune (it brings the batch and scoring modules)
    "segment": ("passes.stage_files", "segment_file"),  # datmo segment
    "extract_features": ("passes.stage_files", "features_file"),  # datmo features
    "track": ("passes.stage_files", "track_file"),  # datmo track
    "warm_up": ("passes.warm", "warm_up"),  # datmo warm-up
    "import_log": ("workflows.importing", "import_log"),  # datmo import
    "ImportResult": ("workflows.importing", "ImportResult"),
    "simulate": ("workflows.simulating", "simulate"),  # datmo simulate
    "SimulateResult": ("workflows.simulating", "SimulateResult"),
    "emulate": ("workflows.emulating", "emulate"),  # datmo emulate
    "Emulation": ("workflows.emulating", "Emulation"),
    "play": ("workflows.playing", "play"),  # datmo play
    "Player": ("workflows.playing", "Player"),
    "node": ("workflows.ros_node", "node"),  # datmo node
    "LiveNode": ("workflows.ros_node", "LiveNode"),
    "train_legs": ("workflows.training", "train_legs"),  # datmo train-legs
    "LegTraining": ("workflows.training", "LegTraining"),
    "export": ("workflows.exporting", "export_files"),  # datmo export
    "ExportResult": ("workflows.exporting", "ExportResult"),
    "info": ("workflows.inspecting", "info"),  # datmo info
    "config": ("workflows.inspecting", "config"),  # datmo config
}


def __getattr__(name: str):
    """The functions of _LAZY, imported on first use: the commands' own calls, not copies of them."""
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(f"{__package__}.{module}"), attr)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def dtype(columns: dict[str, str]) -> np.dtype:
    """The numpy structured dtype of a table of `columns` (strings as Python objects)."""
    return np.dtype([(name, _NUMPY[t]) for name, t in columns.items()])


def _table(batches: Iterator[_export.Batch], columns: dict[str, str]) -> np.ndarray:
    """The rows of `batches` as one structured array of `columns` (a float absent from a row is NaN)."""
    parts = []
    for b in batches:
        if not b.n:
            continue
        part = np.zeros(b.n, dtype(columns))
        for name, t in columns.items():
            if name in b.values:
                part[name] = b.values[name]
            elif t in ("float32", "float64"):
                part[name] = np.nan
            else:
                raise ValueError(f"column {name} missing from a batch")  # a bug: every row has it
        parts.append(part)
    return np.concatenate(parts) if parts else np.zeros(0, dtype(columns))


def _dataframe(table: np.ndarray) -> pandas.DataFrame:
    pd = require("pandas", for_="DataFrames")
    return pd.DataFrame({name: table[name] for name in table.dtype.names})


class Log:
    """A log datmo wrote (`datmo run`, `datmo track`, `process`): its tracks and features, read on demand."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.contents = mcapio.summary(self.path)  # InputError when it is not a readable MCAP log
        self.name = os.fsdecode(path)

    def __repr__(self) -> str:
        return f"Log({self.name!r}: {self.scans} scans, tracks {'yes' if self.has_tracks else 'no'})"

    def _count(self, topic: str) -> int:
        ch = self.contents.topics().get(topic)
        return ch.count if ch is not None else 0

    @property
    def scans(self) -> int:
        """Messages on /scan."""
        return self._count(mcapio.TOPIC_SCAN)

    @property
    def has_tracks(self) -> bool:
        return self._count(mcapio.TOPIC_TRACKS) > 0

    def read_scans(self) -> ScanRun:
        """Every scan of /scan, whole: .stamps (N,) int64 ns, .ranges (N, n_beams) float32 m (inf: no return),
        .geometry (angle_min, angle_increment, n_beams, range_min, range_max, frame_id)."""
        return mcapio.read_run(self.path)

    def poses(self) -> np.ndarray | None:
        """The scanner's pose at every scan, (N, 3): x m, y m, yaw rad in the odometry frame, from /odom (and the
        scanner's mount in /tf_static), as datmo tracks in it; None when the log has no odometry."""
        from .passes.streaming import LogStream

        stream = LogStream(self.path)
        if stream.odometry is None or not len(stream.odometry):
            return None
        return stream.odometry.at(self.read_scans().stamps)

    def _rows(self, topic: str) -> Iterator[_export.Batch]:
        _export.require_channel(self.contents, topic, _export.ROWS[topic][0])
        for _, batch in _export.row_batches(self.path, topic, self.name):
            yield batch

    def tracks(self) -> np.ndarray:
        """Every track's state after every scan: a structured array of TRACK_COLUMNS (the export's tracks
        table: class, mobility and status as names; world_* NaN without odometry). MissingChannelError when
        the log has no /datmo/tracks (run `process` or `datmo run` on it first)."""
        return _table(self._rows(mcapio.TOPIC_TRACKS), TRACK_COLUMNS)

    def features(self) -> np.ndarray:
        """Every line, circle, blob, point and leg of every scan: a structured array of FEATURE_COLUMNS (kind says
        which; a float that does not describe the kind is NaN). MissingChannelError without /datmo/features."""
        return _table(self._rows(mcapio.TOPIC_FEATURES), FEATURE_COLUMNS)

    def tracks_dataframe(self) -> pandas.DataFrame:
        """tracks() as a pandas DataFrame (needs pandas: pip install 'datmo-cli[pandas]')."""
        require("pandas", for_="DataFrames")
        return _dataframe(self.tracks())

    def features_dataframe(self) -> pandas.DataFrame:
        """features() as a pandas DataFrame (needs pandas)."""
        require("pandas", for_="DataFrames")
        return _dataframe(self.features())


def open_log(path: str | os.PathLike) -> Log:
    """The log at `path` (an MCAP file datmo wrote or can read)."""
    return Log(path)


def process(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    config: Config = None,
    force: bool = False,
    markers: bool = False,
    covariance: bool = False,
) -> Log:
    """Segment, extract features and track the MCAP log `src` into `out` (what `datmo run` does for one input,
    without the report), and open the output. `config`: a DatmoConfig, a TOML file (as --config), a dict of
    overrides such as {"track": {"gate": 9.0}}, or None for the defaults; `force`: replace an existing `out`;
    `markers`: also write the Foxglove markers; `covariance`: store the tracks' covariance (else NaN). Convert
    a bag or CARMEN log with `datmo import` first."""
    from .passes.pipeline import process_file

    cfg = _config(config)
    process_file(
        src,
        out,
        force=force,
        config=cfg,
        markers=markers,
        covariance=covariance,
        command_line=f"datmo_cli.api.process({os.fsdecode(src)!r}, {os.fsdecode(out)!r})",
    )
    return Log(out)


def evaluate(
    file: str | os.PathLike,
    *,
    gt_csv: str | os.PathLike | None = None,
    match_radius: float = 0.5,
    include_occluded: bool = False,
    exclude_static: bool = False,
    progress=None,
) -> dict:
    """`datmo evaluate FILE` (docs/report.md): score a tracked log against ground truth, its
    /datmo/ground_truth channel or `gt_csv` (stamp_ns,id,x,y in the sensor frame, metres). Returns {"file",
    "ground_truth", "match_radius_m", "scores": {"all": {...}, "person": {...}, ...}}: MOTA, MOTP (m), IDF1,
    HOTA, DetA, AssA, LocA, counts, per class. `match_radius` metres; `include_occluded`: also score movers no
    beam hits; `exclude_static`: leave out tracks classified static; `progress(done, total, stage)`. Needs
    the eval extra (MissingExtraError without it)."""
    from .evaluate import require_scoring
    from .evaluate.files import score_file

    require_scoring()
    return score_file(
        Path(file),
        gt_csv=Path(gt_csv) if gt_csv is not None else None,
        match_radius=match_radius,
        include_occluded=include_occluded,
        exclude_static=exclude_static,
        progress=progress,
    )


class LiveTracker:
    """Scans in one at a time, tracks out: segmentation, features and tracking of each scan as it comes, in the
    sensor frame, or in the world frame when every scan comes with the scanner's pose.

    `angle_min`, `angle_increment` (radians, counter-clockwise, x forward), `n_beams`, `range_min` and
    `range_max` (metres) describe the scans, as a sensor_msgs/LaserScan does; `frame_id` names their frame.
    `config` as for `process`; `name` fills the tables' file column. `update` returns the tracks after each
    scan as rows of TRACK_COLUMNS (the same table as Log.tracks()), and the same tracks `datmo run` gives for
    those scans when it runs without scan matching (a log with odometry, or a still scanner)."""

    def __init__(
        self,
        angle_min: float,
        angle_increment: float,
        n_beams: int,
        range_min: float,
        range_max: float,
        *,
        frame_id: str = "laser",
        config: Config = None,
        name: str = "live",
    ) -> None:
        from .logs.scan import ScanGeometry

        self.geometry = ScanGeometry(
            float(angle_min),
            float(angle_increment),
            int(n_beams),
            float(range_min),
            float(range_max),
            frame_id=frame_id,
        )
        self.config = _config(config)
        self.name = name
        self.scans = 0
        self._stages = None
        self._odometry = None
        self._last: int | None = None

    def update(self, ranges: np.ndarray, stamp_ns: int, pose: tuple[float, float, float] | None = None) -> np.ndarray:
        """Process one scan: `ranges` (n_beams,) metres (inf or NaN: no return), `stamp_ns` its time (int64 ns,
        after the previous scan's), `pose` the scanner's (x m, y m, yaw rad) in the world frame, given with every
        scan or with none. Returns the tracks after it (TRACK_COLUMNS; scan counts the scans given, from 0)."""
        from .logs.scan import Odometry, ScanRun
        from .passes.pipeline import RunStages
        from .passes.streaming import Block

        r = np.asarray(ranges, np.float32)
        if r.shape != (self.geometry.n_beams,):
            raise InputError(
                f"{self.name}: a scan of {r.shape} ranges; this tracker's scans have {self.geometry.n_beams} beams"
            )
        stamp = int(stamp_ns)
        if self._last is not None and stamp <= self._last:
            raise InputError(f"{self.name}: scan {self.scans} stamped {stamp} ns, not after the previous {self._last}")
        if self._stages is None:
            if pose is not None:
                self._odometry = Odometry(np.zeros(1, np.int64), np.zeros(1), np.zeros(1), np.zeros(1))
            self._stages = RunStages(self._odometry, self.geometry, self.config, markers=False)
        if (pose is None) != (self._odometry is None):
            raise InputError(
                f"{self.name}: scan {self.scans} "
                + ("has no pose; the first had one" if pose is None else "has a pose; the first had none")
                + ": give a pose with every scan or with none"
            )
        if pose is not None:  # the poses RunStages interpolates at this scan: this scan's
            o = self._odometry
            o.stamps[0], (o.x[0], o.y[0], o.theta[0]) = stamp, (float(v) for v in pose)
        run = ScanRun(np.array([stamp], np.int64), r[None, :], self.geometry)
        payload = self._stages(Block(self.scans, run))[mcapio.TOPIC_TRACKS][2][0]
        decoded = cdr.decode(types.TRACKS, payload)
        self.scans += 1
        self._last = stamp
        return _table(iter([_export.track_batch(self.name, self.scans - 1, [decoded])]), TRACK_COLUMNS)
