"""`datmo run`'s stages over a log, and reading processed logs for the plot.

`RunStages` is `datmo run`'s one pass (segmentation, features, tracking) over each block of a streamed log, a
block's path read in `RunStages.step`: perceive, track, give (its channels, and the report fed from the same
arrays); `process_file` runs it over a file, `derive` over a run held in memory. The stage commands' passes
(`track_file`, `features_file`, `segment_file`) are in stage_files. They all write their channels through
streaming.write_derived, so `datmo run`'s output holds the same payloads as the three stages run one after
another, without intermediate files.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ..logs import mcapio

if TYPE_CHECKING:
    from ..report import RunData
    from .config import DatmoConfig
    from .stages import TrackStream

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
    from ..report import RunData  # here, not at the top: the stages need no report module

    topics = REPORT_TOPICS + ((mcapio.TOPIC_GROUND_TRUTH,) if ground_truth else ())
    return RunData.from_log(mcapio.read_log(path, topics=topics), keep_scans=keep_scans)


# ------------------------------------------------------------------------------------------ datmo run


def estimated_odometry(run, odometry, mode: str) -> tuple:
    """(odometry to track in, {"/odom": channel} when it was estimated from the scans here, else {}): a log
    without odometry whose scanner moves is tracked in poses from scan matching (see perception.egomotion),
    written to /odom (frame scan_odom) so the output holds the frame its world positions are in."""
    from ..logs import types
    from ..perception.egomotion import odometry_for

    odometry, estimated = odometry_for(run, odometry, mode)
    if not estimated:
        return odometry, {}
    return odometry, {mcapio.TOPIC_ODOM: (types.ODOMETRY, odometry.stamps, mcapio.encode_odometry(odometry))}


def odometry_channel(odometry, block) -> tuple:
    """The /odom channel (msgtype, stamps, payloads) of a block's scans from odometry estimated at every scan."""
    from ..logs import types

    o, a, b = odometry, block.first, block.first + len(block.run)
    part = type(o)(o.stamps[a:b], o.x[a:b], o.y[a:b], o.theta[a:b], o.frame_id, o.child_frame_id)
    return types.ODOMETRY, part.stamps, mcapio.encode_odometry(part)


def derived_topics(
    *, odom: bool = False, segments: bool = False, features: bool = False, tracks: bool = False, markers: bool = False
) -> dict[str, str]:
    """{topic: message type} of the channels the stages write, in writing order: /odom (estimated here),
    /datmo/segments, /datmo/features with /datmo/landmarks (and /datmo/markers/features), /datmo/tracks (and
    /datmo/markers/tracks)."""
    from ..logs import types

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
    return RunStages(
        odometry,
        stream.geometry,
        config,
        estimated=estimated,
        markers=markers,
        covariance=covariance,
        hindsight=True,
    )


def hindsight_provenance(used: bool, track) -> dict:
    """What an output's provenance says of hindsight (tracking.hindsight): whether its tracks were smoothed and
    labelled over a lag, and the lag (s; 0 when not used)."""
    return {"used": bool(used), "lag_s": float(track.hindsight_lag) if used else 0.0}


PERCEIVE_AHEAD = 2  # blocks whose perception may run ahead of the tracking: one block's wait is the next's slack


class Perceived(NamedTuple):
    """What perceiving a block gave: its channels but the tracks ({topic: (msgtype, stamps, payloads)}: /odom
    when estimated here, then the perception's) and its perception.features.RunFeatures."""

    channels: dict[str, tuple]
    features: Any


class RunStages:
    """Segmentation, features and tracking of one log, block by block (the stages of `datmo run`): `step(block)`
    gives a block's derived channels at once, `pipelined(blocks)` each block's as its tracks are final. The
    scans' `geometry` (log.scan.ScanGeometry) builds the tracker here. `config`: the DatmoConfig (None: the
    defaults); `estimated`: the odometry was estimated from the scans, and its poses are written to /odom block
    by block; `markers`: also make the Foxglove markers; `covariance`: keep the tracks' covariance (else NaN);
    `report`: a report.RunAccumulator fed each block's scans, features, landmarks and tracks from the arrays
    the stages made (the report of the output without reading it; feed_report)."""

    def __init__(
        self,
        odometry,
        geometry,
        config: DatmoConfig | None = None,
        *,
        estimated: bool = False,
        markers: bool = True,
        covariance: bool = True,
        report=None,
        hindsight: bool = False,
    ) -> None:
        from .config import DatmoConfig
        from .feature_channels import FeatureStream
        from .stages import TrackStream, leg_threshold_of

        self.config = config or DatmoConfig()
        self.odometry = odometry
        self.estimated = estimated
        self.markers = markers
        self.covariance = covariance
        self.report = report
        self.hindsight = hindsight and self.config.track.hindsight_lag > 0
        self.features = FeatureStream(self.config.features, odometry)
        model = self.config.features.leg_model
        self.tracking: TrackStream = TrackStream(
            geometry,
            odometry=odometry,
            params=self.config.track,
            markers=markers,
            learned=model != "paper",
            leg_threshold=leg_threshold_of(model),
            covariance=covariance,
            hindsight=self.hindsight,
        )

    def derived(self) -> dict[str, str]:
        """{topic: message type} of the channels the stages write, in writing order."""
        return derived_topics(odom=self.estimated, segments=True, features=True, tracks=True, markers=self.markers)

    def effective(self) -> dict:
        """The effective parameters, as provenance records them."""
        from ..perception.features import leg_model_provenance

        features, track = self.config.features, self.config.track
        return {
            "features": features.to_dict(),
            "track": track.to_dict(),
            "leg_model": leg_model_provenance(features.leg_model),
            "config": self.config.to_dict(),
            "hindsight": hindsight_provenance(self.hindsight, track),
        }

    def step(self, block) -> dict[str, tuple]:
        """One block's path through the stages, its channels at once: causal tracks (the live paths: play,
        record --live, node, the API's LiveTracker). A RunStages with hindsight gives its blocks through
        `pipelined`, whose steps are these three, spread over blocks."""
        if self.hindsight:
            raise ValueError("the stages with hindsight give their blocks through pipelined()")
        perceived = self.perceive(block)
        tracks = self.track(block, perceived)
        return self.give(block, perceived, tracks)

    __call__ = step  # a streaming.Stage

    def pipelined(self, blocks: Iterable) -> Iterator[tuple[Any, dict[str, tuple]]]:
        """(block, its derived channels) for each block in order: `step`'s perceive, track and give, with the
        perception of the next blocks (up to PERCEIVE_AHEAD) on a thread of its own beside this one's tracking,
        encoding and writing when there are two threads or more (perception.threads, `--threads`; the compiled
        kernels release the GIL), and, with hindsight (`datmo run`, `datmo track`), a block given once the tracks
        of its scans are final (tracking.hindsight: up to hindsight_lag s of scans later; memory holds the blocks
        perceived and tracked meanwhile). The channels are the same for any thread count."""
        perceived = self._perceived(blocks)
        tracked = ((block, made, self.track(block, made)) for block, made in perceived)
        for block, made, tracks in held_until_tracked(tracked, self.tracking):
            yield block, self.give(block, made, tracks)

    def perceive(self, block) -> Perceived:
        """Segmentation, features and landmarks of the block's scans (and its /odom channel when estimated)."""
        channels = {mcapio.TOPIC_ODOM: odometry_channel(self.odometry, block)} if self.estimated else {}
        made, features = self.features.block(block.run, markers=self.markers)
        return Perceived(channels | made, features)

    def track(self, block, perceived: Perceived):
        """The stages.TrackedRun tracking gives now: the block's scans' (causal), or with hindsight those of
        the scans whose tracks are final (earlier blocks' among them)."""
        from .stages import iter_run_features

        return self.tracking.block(block.run, iter_run_features(perceived.features))

    def give(self, block, perceived: Perceived, tracks) -> dict[str, tuple]:
        """The block's channels ({topic: (msgtype, stamps, payloads)}, writing order) from what perceiving it
        gave and the TrackedRun of its own scans; the report, when kept, is fed from the same arrays."""
        if self.report is not None:
            feed_report(self.report, block.run, perceived.features, tracks)
        return perceived.channels | self.tracking.channels(tracks)

    def _perceived(self, blocks: Iterable) -> Iterator[tuple[Any, Perceived]]:
        """(block, perceive(block)) for each block in order (see pipelined)."""
        from ..perception import threads as TH

        n = TH.resolve(None)
        if n < 2:
            for block in blocks:
                yield block, self.perceive(block)
            return
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        self.features.threads = n - 1
        with ThreadPoolExecutor(1, thread_name_prefix="datmo-perception") as pool:
            ahead: deque = deque()  # perceived or queued, in order (one worker: FeatureStream's state is ordered)
            try:
                for block in blocks:
                    ahead.append((block, pool.submit(self.perceive, block)))
                    if len(ahead) > PERCEIVE_AHEAD:
                        done, made = ahead.popleft()
                        yield done, made.result()
                while ahead:
                    done, made = ahead.popleft()
                    yield done, made.result()
            finally:  # stopped early (an error, Ctrl-C): the queued blocks are not perceived for nothing
                for _, made in ahead:
                    made.cancel()


def held_until_tracked(items: Iterable[tuple], tracking: TrackStream) -> Iterator[tuple]:
    """Blocks held until their tracks are given: `items` yields (block, what perceiving it gave, TrackedRun of
    the scans `tracking` gave with that block: with hindsight, earlier scans' and not the newest); this yields
    (block, what perceiving it gave, the TrackedRun of the block's own scans) in order, each as soon as its
    scans' tracks are all given, and the rest after the last block (`tracking.finish()` then). Without
    hindsight each block is given at once with its own TrackedRun."""
    from collections import deque

    from .stages import split_tracked

    held: deque = deque()
    ready: list = []  # TrackedRuns given and not yet assigned to a block, in order

    def give():
        while held and sum(len(t.stamps) for t in ready) >= len(held[0][0].run):
            block, made = held.popleft()
            tracks, ready[:] = split_tracked(ready, len(block.run))
            yield block, made, tracks

    for block, made, tracked in items:
        held.append((block, made))
        ready.append(tracked)
        yield from give()
    if held:
        ready.append(tracking.finish())
        yield from give()
    if held:
        raise RuntimeError(f"tracking gave too few scans' tracks for {len(held)} blocks")


def feed_report(report, run, features, tracked) -> None:
    """Add one block's scans, features (their counts), landmarks (the frame, the database after the block's
    last scan) and track states to a report.RunAccumulator, from the arrays the stages made (a RunFeatures, a
    TrackedRun): what report.stream_run reads back from the output's messages."""
    import numpy as np

    from ..report import FEATURE_KINDS

    report.add_scans(run.stamps, run.geometry.n_beams)
    report.add_features(
        len(run),
        {k: np.diff(np.asarray(getattr(features, f"{k[:-1]}_offsets"))).astype(np.int64) for k in FEATURE_KINDS},
    )
    if len(run):
        report.add_landmarks(features.landmark_frame, features.landmarks.final())
    offsets, items = tracked.all_tracks()
    if len(items):
        report.add_tracks(np.repeat(np.asarray(tracked.stamps, np.int64), np.diff(offsets)), items)


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
    stages = RunStages(
        odometry,
        run.geometry,
        config,
        estimated=bool(odom_channel),
        markers=markers,
        covariance=covariance,
        hindsight=True,
    )
    if progress:
        progress(0, len(run))
    derived = next(stages.pipelined([Block(0, run)]))[1]
    if progress:
        progress(len(run), len(run))
    return derived, stages.effective()


def write_options(
    force: bool, command_line: str | None, block_scans: int | None, progress: Callable[[int, int], None] | None
) -> dict:
    """The keywords of streaming.write_derived that every pass over a file passes on from its caller as they are:
    `force` (overwrite `out`), `command_line` (for the provenance), `block_scans` (scans per block; None: the
    default, streaming.BLOCK_SCANS) and `progress(done, total)`."""
    from .streaming import BLOCK_SCANS

    return {
        "force": force,
        "command_line": command_line,
        "block_scans": block_scans or BLOCK_SCANS,
        "progress": progress,
    }


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
    from ..logs import bagdir
    from .streaming import LogStream, write_derived

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
            **write_options(force, command_line, block_scans, progress),
            input_name=input_name,
            origin=origin,
            report=report,
        )
