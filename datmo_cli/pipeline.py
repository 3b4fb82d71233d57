"""The stages behind the commands that turn a log into a log, and reading processed logs for the plot.

`RunStages` is `datmo run`'s one pass (segmentation, features, tracking) over each block of a streamed log;
`track_file`, `features_file` and `segment_file` are the stage commands' passes, and `derive` runs the same
stages on a run held in memory. They all write their channels through streaming.write_derived, so `datmo run`'s
output holds the same payloads as the three stages run one after another, without intermediate files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import InputError
from .log import mcapio

if TYPE_CHECKING:
    from .config import DatmoConfig
    from .report import RunData

REPORT_TOPICS = (
    mcapio.TOPIC_SCAN,
    mcapio.TOPIC_ODOM,
    mcapio.TOPIC_FEATURES,
    mcapio.TOPIC_LANDMARKS,
    mcapio.TOPIC_TRACKS,
)


def read_run_data(path: str | Path, *, keep_scans: bool = False, ground_truth: bool = False) -> RunData:
    """The channels of a processed log that the plot of `datmo report` and `datmo run` needs, decoded whole
    (memory grows with the log; the report alone streams: report.summarise_file).

    Raises MissingChannelError naming the command to run first when /scan or /datmo/tracks is missing.
    """
    from .report import RunData  # here, not at the top: the stages need no report module

    topics = REPORT_TOPICS + ((mcapio.TOPIC_GROUND_TRUTH,) if ground_truth else ())
    return RunData.from_log(mcapio.read_log(path, topics=topics), keep_scans=keep_scans)


# ------------------------------------------------------------------------------------------ datmo run


def warm_up() -> None:
    """Compile every numba kernel of the pipeline in this process (or load it from numba's cache) on short
    simulated runs of the hall (people, a platform, columns, benches, occlusions) and of the patrol scene
    (odometry), before any input's clock starts and before worker processes start: they then inherit the
    compiled kernels (fork) or find the cache complete (spawn), and never compile one kernel at once (a
    first run after an install would otherwise have every worker writing the same cache files)."""
    from .numba_runtime import prepare
    from .perception.egomotion import odometry_for
    from .sim.simulate import simulate_scene

    prepare()
    for scene in ("hall", "patrol"):
        sim = simulate_scene(scene, duration=8.0)
        derive(sim.run, sim.odometry, markers=True)  # the markers' kernels too (--markers, the live view)
    odometry_for(sim.run, None, "on")  # scan matching, for logs without odometry


def estimated_odometry(run, odometry, mode: str) -> tuple:
    """(odometry to track in, {"/odom": channel} when it was estimated from the scans here, else {}): a log
    without odometry whose scanner moves is tracked in poses from scan matching (see perception.egomotion),
    written to /odom (frame scan_odom) so the output holds the frame its world positions are in."""
    from .log import types
    from .perception.egomotion import odometry_for

    odometry, estimated = odometry_for(run, odometry, mode)
    if not estimated:
        return odometry, {}
    return odometry, {mcapio.TOPIC_ODOM: (types.ODOMETRY, odometry.stamps, mcapio.encode_odometry(odometry))}


def odometry_channel(odometry, block) -> tuple:
    """The /odom channel (msgtype, stamps, payloads) of a block's scans from odometry estimated at every scan."""
    from .log import types

    o, a, b = odometry, block.first, block.first + len(block.run)
    part = type(o)(o.stamps[a:b], o.x[a:b], o.y[a:b], o.theta[a:b], o.frame_id, o.child_frame_id)
    return types.ODOMETRY, part.stamps, mcapio.encode_odometry(part)


def derived_topics(
    *, odom: bool = False, segments: bool = False, features: bool = False, tracks: bool = False, markers: bool = False
) -> dict[str, str]:
    """{topic: message type} of the channels the stages write, in writing order: /odom (estimated here),
    /datmo/segments, /datmo/features with /datmo/landmarks (and /datmo/markers/features), /datmo/tracks (and
    /datmo/markers/tracks)."""
    from .log import types

    out = {mcapio.TOPIC_ODOM: types.ODOMETRY} if odom else {}
    if segments:
        out[mcapio.TOPIC_SEGMENTS] = types.SEGMENTS
    if features:
        out |= {mcapio.TOPIC_FEATURES: types.FEATURES, mcapio.TOPIC_LANDMARKS: types.LANDMARKS}
        if markers:
            out[mcapio.TOPIC_MARKERS_FEATURES] = types.MARKER_ARRAY
    if tracks:
        out[mcapio.TOPIC_TRACKS] = types.TRACKS
        if markers:
            out[mcapio.TOPIC_MARKERS_TRACKS] = types.MARKER_ARRAY
    return out


def open_stages(
    stream, config: DatmoConfig | None = None, *, markers: bool = True, covariance: bool = True
) -> RunStages:
    """The stages of a streamed log (a streaming.LogStream) in the odometry it is tracked in: the log's own,
    else (ego-motion mode of config.track) poses estimated from its scans, then written to /odom (see
    streaming.stream_odometry). Every pass over a log reads its odometry here, once."""
    from .config import DatmoConfig
    from .streaming import stream_odometry

    config = config or DatmoConfig()
    odometry, estimated = stream_odometry(stream, config.track.ego_motion)
    return RunStages(odometry, config, estimated=estimated, markers=markers, covariance=covariance)


class RunStages:
    """Segmentation, features and tracking of one log, block by block (the stages of `datmo run`): call it
    with each Block in order; it returns the block's derived channels. `config`: the DatmoConfig (None: the
    defaults); `estimated`: the odometry was estimated from the scans, and its poses are written to /odom block
    by block; `markers`: also make the Foxglove markers; `covariance`: keep the tracks' covariance (else NaN);
    `report`: a report.RunAccumulator fed each block's scans, features, landmarks and tracks as they are made
    (the report of the output without reading it; feed_report)."""

    def __init__(
        self,
        odometry,
        config: DatmoConfig | None = None,
        *,
        estimated: bool = False,
        markers: bool = True,
        covariance: bool = True,
        report=None,
    ) -> None:
        from .config import DatmoConfig
        from .feature_channels import FeatureStream

        self.config = config or DatmoConfig()
        self.odometry = odometry
        self.estimated = estimated
        self.markers = markers
        self.covariance = covariance
        self.features = FeatureStream(self.config.features, odometry)
        self.tracking = None
        self.report = report

    def derived(self) -> dict[str, str]:
        """{topic: message type} of the channels the stages write, in writing order."""
        return derived_topics(odom=self.estimated, segments=True, features=True, tracks=True, markers=self.markers)

    def effective(self) -> dict:
        """The effective parameters, as provenance records them."""
        from .perception.features import leg_model_provenance

        features, track = self.config.features, self.config.track
        return {
            "features": features.to_dict(),
            "track": track.to_dict(),
            "leg_model": leg_model_provenance(features.leg_model),
            "config": self.config.to_dict(),
        }

    def __call__(self, block) -> dict[str, tuple]:
        from .stages import TrackStream, iter_run_features, leg_threshold_of

        run = block.run
        out = {}
        if self.estimated:
            out[mcapio.TOPIC_ODOM] = odometry_channel(self.odometry, block)
        channels, features = self.features.block(run, markers=self.markers)
        out |= channels
        if self.tracking is None:
            model = self.config.features.leg_model
            self.tracking = TrackStream(
                run.geometry,
                odometry=self.odometry,
                params=self.config.track,
                markers=self.markers,
                learned=model != "paper",
                leg_threshold=leg_threshold_of(model),
                covariance=self.covariance,
            )
        tracked = self.tracking.block(run, iter_run_features(features))
        out |= self.tracking.channels(tracked)
        if self.report is not None:
            feed_report(self.report, run, features, out[mcapio.TOPIC_LANDMARKS][2], tracked)
        return out


def feed_report(report, run, features, landmark_payloads: list[bytes], tracked) -> None:
    """Add one block's scans, features (their counts), landmarks (the frame of the first message, the
    database of the block's last) and track states to a report.RunAccumulator, from the arrays the stages
    made: what report.stream_run would read back from the output's messages."""
    import numpy as np

    from .log import cdr, types
    from .report import FEATURE_KINDS

    report.add_scans(run.stamps, run.geometry.n_beams)
    report.add_features(
        len(run),
        {k: np.diff(np.asarray(getattr(features, f"{k[:-1]}_offsets"))).astype(np.int64) for k in FEATURE_KINDS},
    )
    if landmark_payloads:
        frame = cdr.decode(types.LANDMARKS, landmark_payloads[0])["frame_id"] if report.landmark_frame is None else ""
        report.add_landmarks(frame, cdr.decode(types.LANDMARKS, landmark_payloads[-1])["landmarks"])
    counts = [len(t) for t in tracked.tracks]
    if sum(counts):
        report.add_tracks(np.repeat(np.asarray(tracked.stamps, np.int64), counts), np.concatenate(tracked.tracks))


def derive(
    run,
    odometry,
    config: DatmoConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    *,
    markers: bool = False,
    covariance: bool = False,
) -> tuple[dict[str, tuple], dict]:
    """Every derived channel of a run held in memory, {topic: (msgtype, stamps, payloads)}, and the effective
    parameters; `config`: the DatmoConfig (None: the defaults). The same stages as process_file, on one
    block (`markers`, `covariance` as there)."""
    from .config import DatmoConfig
    from .streaming import Block

    config = config or DatmoConfig()
    odometry, odom_channel = estimated_odometry(run, odometry, config.track.ego_motion)
    stages = RunStages(odometry, config, estimated=bool(odom_channel), markers=markers, covariance=covariance)
    if progress:
        progress(0, len(run))
    derived = stages(Block(0, run))
    if progress:
        progress(len(run), len(run))
    return derived, stages.effective()


def process_file(
    src: str | Path,
    out: str | Path,
    *,
    force: bool = False,
    config: DatmoConfig | None = None,
    command_line: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    markers: bool = False,
    covariance: bool = False,
    bag_dir: bool = False,
    block_scans: int | None = None,
    input_name: str | None = None,
    origin: str | Path | None = None,
    report=None,
) -> int:
    """Segment, extract features and track `src` in one streaming pass into `out` (see module docstring and
    streaming); returns the number of scans. `config`: the DatmoConfig (None: the defaults), recorded whole in
    the provenance; `progress(done, total)` is called as scans are processed; `markers`: also write the Foxglove
    markers; `covariance`: store the tracks' covariance (else NaN); `input_name`: what the output's provenance
    calls the input (default its path); `origin`: the file or bag folder `src` was converted from (`src` a
    temporary copy of a bag), which provenance hashes and names instead. With `bag_dir`, `out` is the log file
    of a ROS 2 bag folder (log.bagdir.member_path), and the folder is written whole. `report`: a
    report.RunAccumulator that gathers the output's report as it is written (RunStages), so the report needs
    no second pass over the output."""
    from .log import bagdir
    from .streaming import BLOCK_SCANS, LogStream, write_derived

    stream = src if isinstance(src, LogStream) else LogStream(src)
    src = stream.path
    stages = open_stages(stream, config, markers=markers, covariance=covariance)
    stages.report = report
    origin = Path(origin) if origin is not None else src
    with bagdir.output(Path(out).parent if bag_dir else out, bag_dir, force=force, inputs=[origin]) as dst:
        return write_derived(
            stream,
            dst,
            command="run",
            params=stages.effective(),
            derived=stages.derived(),
            stage=stages,
            force=force,
            command_line=command_line,
            block_scans=block_scans or BLOCK_SCANS,
            progress=progress,
            input_name=input_name,
            origin=origin,
            report=report,
        )


def _provenance_entries(log, key: str) -> list[dict]:
    """The JSON objects a log's provenance records under `key`, its own datmo.params first, then its input's
    ({} for one that does not parse as an object)."""
    import json

    out = []
    for name in ("datmo.params", "input/datmo.params"):
        raw = log.metadata.get(name, {}).get(key)
        if raw:
            try:
                value = json.loads(raw)
            except ValueError:
                value = {}
            out.append(value if isinstance(value, dict) else {})
    return out


def features_leg_model(log) -> str:
    """The leg detector a log's /datmo/features were made with, from its provenance ("paper" for features
    made before datmo had a detector, whose legs are the paper's circles)."""
    entries = _provenance_entries(log, "features")
    return str(entries[0].get("leg_model", "paper")) if entries else "paper"


def features_leg_threshold(log, used: str) -> float:
    """The leg threshold of the detector a log's /datmo/features were made with (`used`, features_leg_model): the
    threshold its provenance records, else that of the model `used` names (0.5 for the paper's rule)."""
    from .stages import leg_threshold_of

    if used == "paper":
        return 0.5
    for entry in _provenance_entries(log, "leg_model"):
        value = entry.get("threshold")
        if isinstance(value, int | float) and 0.0 <= value <= 1.0:
            return float(value)
    return leg_threshold_of(used)


def track_file(
    src: str | Path,
    out: str | Path,
    *,
    force: bool = False,
    config: DatmoConfig | None = None,
    leg_model: str | None = None,
    command_line: str | None = None,
    markers: bool = False,
    covariance: bool = False,
    block_scans: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[int, bool]:
    """Track `src` into `out` in one streaming pass (its channels copied, /datmo/tracks added, and
    /datmo/markers/tracks with `markers`; the tracks' covariance is stored with `covariance`, else NaN).
    Features come from src's /datmo/features when present (people then by the rule of the leg detector they
    were made with; `leg_model`, when given, must be that one); else
    segmentation and features run here (with `leg_model` when given) and their channels are written too,
    as datmo run writes them. `config`: the DatmoConfig (None: the defaults), recorded whole in the provenance.
    Returns (scans, whether features were computed here)."""
    from .config import DatmoConfig
    from .perception.features import leg_model_provenance
    from .stages import TrackStream, decode_features
    from .streaming import BLOCK_SCANS, LogStream, write_derived

    config = config or DatmoConfig()
    params = config.track
    stream = src if isinstance(src, LogStream) else LogStream(src)
    src = stream.path
    computed = not stream.has(mcapio.TOPIC_FEATURES)
    if not computed:
        used = features_leg_model(stream.log)
        if leg_model is not None and leg_model != used:
            raise InputError(
                f"{src}: its features were made with leg model {used!r}, not {leg_model!r}; run "
                f"datmo features --leg-model {leg_model} on it first, or drop --leg-model"
            )
        if stream.count(mcapio.TOPIC_FEATURES) != stream.n_scans:
            raise InputError(
                f"{src}: {stream.count(mcapio.TOPIC_FEATURES)} messages on {mcapio.TOPIC_FEATURES} "
                f"for {stream.n_scans} scans; run datmo features again"
            )
    stages = open_stages(
        stream,
        config.replace(features={"leg_model": leg_model}) if computed else config,
        markers=markers,
        covariance=covariance,
    )
    odometry, estimated = stages.odometry, stages.estimated
    if computed:
        derived, stage, effective = stages.derived(), stages, stages.effective()
    else:
        state: dict = {}
        derived = derived_topics(odom=estimated, tracks=True, markers=markers)
        threshold = features_leg_threshold(stream.log, used)
        effective = {
            "track": params.to_dict(),
            "leg_model": (leg_model_provenance(used) if used == "paper" else {"model": used, "threshold": threshold}),
            "config": config.to_dict(),
        }

        def stage(block) -> dict:
            run, out = block.run, {}
            if estimated:
                out[mcapio.TOPIC_ODOM] = odometry_channel(odometry, block)
            if "tracking" not in state:
                state["tracking"] = TrackStream(
                    run.geometry,
                    odometry=odometry,
                    params=params,
                    markers=markers,
                    learned=used != "paper",
                    leg_threshold=threshold,
                    covariance=covariance,
                )
            tracking = state["tracking"]
            with mcapio.decoding(stream.path, mcapio.TOPIC_FEATURES):
                features = decode_features(block.aligned[mcapio.TOPIC_FEATURES], block.first)
            return out | tracking.channels(tracking.block(run, features))

    scans = write_derived(
        stream,
        out,
        command="track",
        params=effective,
        derived=derived,
        stage=stage,
        force=force,
        command_line=command_line,
        aligned=() if computed else (mcapio.TOPIC_FEATURES,),
        block_scans=block_scans or BLOCK_SCANS,
        progress=progress,
    )
    return scans, computed


@dataclass
class FeatureCounts:
    """What `features_file` found: scans, and lines, circles, blobs and legs in all; landmarks at the end."""

    scans: int = 0
    lines: int = 0
    circles: int = 0
    blobs: int = 0
    legs: int = 0
    landmarks: int = 0

    def per_scan(self, name: str) -> float:
        return getattr(self, name) / max(self.scans, 1)


def features_file(
    src: str | Path,
    out: str | Path,
    config: DatmoConfig | None = None,
    *,
    resegment: bool = False,
    force: bool = False,
    command_line: str | None = None,
    markers: bool = False,
    block_scans: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FeatureCounts:
    """Extract the features of `src` into `out` in one streaming pass: /datmo/features, /datmo/landmarks (and
    /datmo/markers/features with `markers`), and /datmo/segments unless the input has its own (used unless
    `resegment`).
    `config`: the DatmoConfig (None: the defaults), its features section used and the whole recorded in the
    provenance."""
    from .config import DatmoConfig
    from .feature_channels import FeatureStream, decode_segments
    from .streaming import BLOCK_SCANS, LogStream, write_derived

    config = config or DatmoConfig()
    params = config.features
    stream = src if isinstance(src, LogStream) else LogStream(src)
    src = stream.path
    given = stream.has(mcapio.TOPIC_SEGMENTS) and not resegment
    if given and stream.count(mcapio.TOPIC_SEGMENTS) != stream.n_scans:
        raise InputError(
            f"{src}: {stream.count(mcapio.TOPIC_SEGMENTS)} messages on {mcapio.TOPIC_SEGMENTS} for "
            f"{stream.n_scans} scans; run datmo segment again or pass --resegment"
        )
    features = FeatureStream(params, stream.odometry)
    counts = FeatureCounts()
    derived = derived_topics(segments=not given, features=True, markers=markers)

    def stage(block) -> dict:
        segments = None
        if given:
            with mcapio.decoding(src, mcapio.TOPIC_SEGMENTS):
                segments = decode_segments(block.aligned[mcapio.TOPIC_SEGMENTS], block.first)
        try:
            channels, f = features.block(block.run, segments, markers=markers)
        except InputError as exc:
            if not given:
                raise
            where = f" (scans {block.first}.. of it)" if block.first else ""
            raise InputError(f"{src}: {mcapio.TOPIC_SEGMENTS}{where}: {exc}") from None
        counts.scans += len(f)
        counts.lines, counts.circles = counts.lines + len(f.lines), counts.circles + len(f.circles)
        counts.blobs, counts.legs = counts.blobs + len(f.blobs), counts.legs + len(f.legs)
        counts.landmarks = len(f.landmarks.final())
        return channels

    from .perception.features import leg_model_provenance

    effective = {
        "features": params.to_dict(),
        "leg_model": leg_model_provenance(params.leg_model),
        "config": config.to_dict(),
    }
    write_derived(
        stream,
        out,
        command="features",
        params=effective,
        derived=derived,
        stage=stage,
        force=force,
        command_line=command_line,
        aligned=(mcapio.TOPIC_SEGMENTS,) if given else (),
        block_scans=block_scans or BLOCK_SCANS,
        progress=progress,
    )
    return counts


def segment_file(
    src: str | Path,
    out: str | Path,
    config: DatmoConfig | None = None,
    *,
    force: bool = False,
    command_line: str | None = None,
    block_scans: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> int:
    """Segment every scan of `src` into `out` (its channels plus /datmo/segments) in one streaming pass;
    returns the number of scans. `config`: the DatmoConfig (None: the defaults), its features' c0 and
    min_points used and the whole recorded in the provenance."""
    from .config import DatmoConfig
    from .stages import derive_segments
    from .streaming import BLOCK_SCANS, LogStream, write_derived

    config = config or DatmoConfig()
    params = config.features
    stream = src if isinstance(src, LogStream) else LogStream(src)
    src = stream.path
    effective = {"features": params.to_dict(), "config": config.to_dict()}
    return write_derived(
        stream,
        out,
        command="segment",
        params=effective,
        derived=derived_topics(segments=True),
        stage=lambda block: derive_segments(block.run, params),
        force=force,
        command_line=command_line,
        block_scans=block_scans or BLOCK_SCANS,
        progress=progress,
    )
