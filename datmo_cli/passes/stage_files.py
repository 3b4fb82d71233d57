"""The stage commands' passes over a file: `segment_file`, `features_file` and `track_file` (datmo segment,
features and track), each one streaming pass of a log into a log with the stage's channels added, written through
streaming.write_derived as `datmo run` writes them (pipeline.process_file); and the leg detector a processed
log's features were made with, read from its provenance.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..base.errors import InputError
from ..logs import mcapio
from .pipeline import (
    derived_topics,
    held_until_tracked,
    hindsight_provenance,
    odometry_channel,
    open_stages,
    write_options,
)

if TYPE_CHECKING:
    from .config import DatmoConfig
    from .pipeline import RunStages
    from .streaming import LogStream


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
    src: str | Path | LogStream,
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
    from ..perception.features import leg_model_provenance
    from .config import DatmoConfig
    from .streaming import LogStream, write_derived

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
    stage: RunStages | _TrackFeatures
    if computed:
        derived, stage, effective = stages.derived(), stages, stages.effective()
    else:
        derived = derived_topics(odom=estimated, tracks=True, markers=markers)
        threshold = features_leg_threshold(stream.log, used)
        effective = {
            "track": params.to_dict(),
            "leg_model": (leg_model_provenance(used) if used == "paper" else {"model": used, "threshold": threshold}),
            "config": config.to_dict(),
            "hindsight": hindsight_provenance(params.hindsight_lag > 0, params),
        }
        stage = _TrackFeatures(stream, odometry, estimated, params, used, threshold, markers, covariance)
    scans = write_derived(
        stream,
        out,
        command="track",
        params=effective,
        derived=derived,
        stage=stage,
        aligned=() if computed else (mcapio.TOPIC_FEATURES,),
        **write_options(force, command_line, block_scans, progress),
    )
    return scans, computed


class _TrackFeatures:
    """`datmo track`'s stage on a log with features: its blocks' tracks (with hindsight, see
    pipeline.RunStages.pipelined) and estimated odometry."""

    def __init__(self, stream, odometry, estimated: bool, params, used: str, threshold: float, markers, covariance):
        from .stages import TrackStream

        self.stream, self.odometry, self.estimated = stream, odometry, estimated
        self.tracking = TrackStream(
            stream.geometry,
            odometry=odometry,
            params=params,
            markers=markers,
            learned=used != "paper",
            leg_threshold=threshold,
            covariance=covariance,
            hindsight=True,
        )

    def pipelined(self, blocks):
        """(block, its channels) for each block in order, once its tracks are given."""
        made = ((block, *self._track(block)) for block in blocks)
        for block, channels, tracks in held_until_tracked(made, self.tracking):
            yield block, channels | self.tracking.channels(tracks)

    def _track(self, block) -> tuple[dict, object]:
        from .stages import decode_features

        run, out = block.run, {}
        if self.estimated:
            out[mcapio.TOPIC_ODOM] = odometry_channel(self.odometry, block)
        with mcapio.decoding(self.stream.path, mcapio.TOPIC_FEATURES):
            features = decode_features(block.aligned[mcapio.TOPIC_FEATURES], block.first)
        return out, self.tracking.block(run, features)


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
    src: str | Path | LogStream,
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
    from .streaming import LogStream, write_derived

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
        counts.blobs, counts.legs = (
            counts.blobs + len(f.blobs),
            counts.legs + (len(f.legs) if f.legs is not None else 0),
        )
        counts.landmarks = len(f.landmarks.final()) if f.landmarks is not None else 0
        return channels

    from ..perception.features import leg_model_provenance

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
        aligned=(mcapio.TOPIC_SEGMENTS,) if given else (),
        **write_options(force, command_line, block_scans, progress),
    )
    return counts


def segment_file(
    src: str | Path | LogStream,
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
    from .streaming import LogStream, write_derived

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
        **write_options(force, command_line, block_scans, progress),
    )
