"""Scoring a processed log file against its ground truth (the /datmo/ground_truth channel, or an annotated CSV):
what `datmo evaluate` and `datmo tune` run per log. Positions in the sensor frame, metres; stamps in ns."""

from __future__ import annotations

from pathlib import Path


def score_file(
    path: Path,
    *,
    gt_csv: Path | None = None,
    match_radius: float = 0.5,
    include_occluded: bool = False,
    exclude_static: bool = False,
    progress=None,
) -> dict:
    """Read `path` (and the CSV) and score it: {"file", "ground_truth", "match_radius_m", "scores": {...}};
    `progress(done, total, stage)` as evaluate.evaluate calls it."""
    import numpy as np

    from ..base.errors import InputError, MissingChannelError
    from ..logs import mcapio, types
    from ..report import decode_channel, require
    from . import frames, ground_truth_csv, scoring

    topics = [mcapio.TOPIC_TRACKS] + ([] if gt_csv else [mcapio.TOPIC_GROUND_TRUTH])
    log = mcapio.read_log(path, topics=topics)
    require(log, mcapio.TOPIC_TRACKS)
    with mcapio.decoding(path, mcapio.TOPIC_TRACKS):
        tracks = decode_channel(types.TRACKS, log.messages[mcapio.TOPIC_TRACKS][1])
    hyps = frames.track_frames(
        tracks.stamps,
        tracks.offsets["tracks"],
        tracks.items["tracks"],
        include_coasting=include_occluded,
        exclude_static=exclude_static,
    )
    if gt_csv is not None:
        gt, regions = ground_truth_csv.read_ground_truth_csv(gt_csv), None
        dt = np.diff(np.sort(tracks.stamps))
        tolerance = int(np.median(dt) // 2) if len(dt) else 0  # annotation stamps may be rounded
        source = str(gt_csv)
    else:
        if not log.has(mcapio.TOPIC_GROUND_TRUTH):
            raise MissingChannelError(
                f"{path}: no messages on {mcapio.TOPIC_GROUND_TRUTH}; run datmo simulate "
                "first, or give annotations with --gt FILE.csv (stamp_ns,id,x,y)"
            )
        with mcapio.decoding(path, mcapio.TOPIC_GROUND_TRUTH):
            truth = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
        gt, regions = frames.ground_truth_frames(
            truth.stamps,
            truth.offsets["objects"],
            truth.items["objects"],
            truth.scalars.get("sensor_theta"),
            include_occluded=include_occluded,
        )
        tolerance = 0
        source = mcapio.TOPIC_GROUND_TRUTH
        if not (np.isfinite(gt.x).all() and np.isfinite(gt.y).all()):
            raise InputError(f"{path}: {source} holds positions that are not finite numbers")
    scores = scoring.evaluate(
        gt, hyps, regions=regions, match_radius=match_radius, stamp_tolerance_ns=tolerance, progress=progress
    )
    if scores["all"]["frames_without_tracks"] == len(gt.stamps):
        raise InputError(f"{path}: no Tracks message has the stamp of any ground-truth frame of {source}")
    return {
        "file": str(path),
        "ground_truth": source,
        "match_radius_m": match_radius,
        "include_occluded": include_occluded,
        "exclude_static": exclude_static,
        "scores": scores,
    }
