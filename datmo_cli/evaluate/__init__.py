"""Scoring tracks against ground truth: CLEAR-MOT (MOTA, MOTP), IDF1 and their counts with py-motmetrics, HOTA
(DetA, AssA, LocA) with TrackEval.

What is scored (pure functions over arrays; positions in the sensor frame, metres):
- Targets: ground-truth objects of a mover class (person, circle object, rectangular object:
  GroundTruthObject.CLASS_* 1-3) that move at some time in the run, in the scans where at least one beam
  hits them (`visible`). `include_occluded=True` scores them in every scan, hidden or not.
- Don't-care regions: every other ground-truth object, i.e. scene structure (columns, benches, wall
  corners, walls), movers that never move (a parked platform, a person standing all along) and, by
  default, hidden targets. A track within the match radius of one of them (its extent: an oriented
  length x width rectangle, a segment for walls, a point for corners) and not within the match radius of a
  target is ignored: neither a match nor a false positive (like MOTChallenge's distractors).
- Hypotheses: confirmed tracks (STATUS_CONFIRMED), and coasting ones too with `include_occluded`;
  `exclude_static=True` drops tracks the tracker classifies static.
- Matching: a hypothesis may match a target within `match_radius` metres (Euclidean, sensor frame of the
  scan); motmetrics solves each frame's assignment and keeps previous matches. MOTP is the mean distance
  of matched pairs, metres (lower is better).
- Frames: every ground-truth message (or CSV stamp) is a frame; tracks come from the Tracks message with
  the same stamp (or the nearest within `stamp_tolerance_ns`).
- Per class: targets of class c against hypotheses whose track class is c (Track and GroundTruthObject
  class codes coincide: 1 person, 2 circle object, 3 rectangular object). Tracks of class unknown count
  only in the overall figures.
- HOTA (Luiten et al. 2021, IJCV; TrackEval's implementation): the same targets, hypotheses and frames,
  with the similarity of a target and a hypothesis at distance d metres S = max(0, 1 - d / match_radius)
  (1 on the target, 0 at the match radius and beyond, so no pair farther than CLEAR-MOT's radius matches).
  HOTA, DetA, AssA and LocA are TrackEval's means over the localisation thresholds alpha = 0.05, 0.10, ...,
  0.95: a pair counts as a true positive at alpha when S >= alpha. LocA is then the mean S of matched pairs,
  i.e. 1 - (mean matched distance) / match_radius; it is None when nothing matches. With neither targets
  nor hypotheses HOTA, DetA and AssA are None (undefined), like MOTA without targets.
CSV ground truth (annotated real logs) has targets only: every annotated object, no don't-care regions.

Memory: scoring holds the whole run, and does not stream like the other commands. py-motmetrics'
MOTAccumulator keeps every frame's events (a DataFrame row per match, miss, false positive and switch)
and computes the figures from all of them at the end; IDF1 in particular is one assignment of ground-truth
ids to track ids over the whole run. Feeding the accumulator block by block would save only the decoded
messages (a few numbers per object and frame, next to the accumulator's rows), and which targets count
(`moved_ids`: movers that move at some time) is itself a whole-run fact. Bounding it would mean computing
CLEAR-MOT and IDF1 here from per-id counts instead of motmetrics' events; not done. HOTA likewise needs
the whole run (its matching weighs each pair by the two ids' alignment over all frames): it keeps each
frame's targets x hypotheses similarities, a few numbers per frame.

The modules: evaluate.frames (targets, hypotheses and don't-care regions from the channels),
evaluate.ground_truth_csv (targets from an annotated CSV) and evaluate.scoring (the matching and the figures).
The package re-exports their public names, so `from datmo_cli.evaluate import X` keeps working.
"""

from .frames import (
    MOVER_CLASSES,
    Frames,
    Regions,
    frames_from_channels,
    ground_truth_frames,
    moved_ids,
    target_mask,
    track_frames,
)
from .ground_truth_csv import CLASS_BY_NAME, INT64_MAX, parse_ground_truth_csv, read_ground_truth_csv
from .scoring import (
    HIGHER_IS_BETTER,
    HOTA_METRICS,
    METRICS,
    PROGRESS_EVERY,
    HotaFrames,
    Progress,
    align,
    aligned_hypotheses,
    evaluate,
    hota,
    require_scoring,
)

__all__ = [
    "CLASS_BY_NAME",
    "HIGHER_IS_BETTER",
    "HOTA_METRICS",
    "INT64_MAX",
    "METRICS",
    "MOVER_CLASSES",
    "PROGRESS_EVERY",
    "Frames",
    "HotaFrames",
    "Progress",
    "Regions",
    "align",
    "aligned_hypotheses",
    "evaluate",
    "frames_from_channels",
    "ground_truth_frames",
    "hota",
    "moved_ids",
    "parse_ground_truth_csv",
    "read_ground_truth_csv",
    "require_scoring",
    "target_mask",
    "track_frames",
]
