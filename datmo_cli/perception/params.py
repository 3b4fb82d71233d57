"""Parameters of `datmo segment` and `datmo features` (the `[features]` table of a config file).

Defaults follow Castro, Nunes and Ruano (2004) as restated in docs/method.md where the paper gives a value
(line kept with more than 3 points, r_acc > 0.5 and length > 10 cm, legs of radius 10 cm, d_max 150 cm),
except the minimum segment size: 3, not the paper's 5, so that legs 4-6 m away (3-5 beams of a 0.5°
scan) are still segments and circles (tracking people MOTA on the hall log rises from 0.2 to 0.7 with it);
the rest were tuned on the simulator's logs (`make accuracy`). A circle must also be a well-posed arc
(circle_min_coverage 0.6, circle_residual_ratio 0.8, circle_radius_margin 1 cm, circle_lines_ratio 1.0; 0
turns a test off, all four at 0 is the rule before): on the CARMEN office logs circles per scan fall from
3.2 to 1.3 (csail) and 4.4 to 1.9 (freiburg-079), none at a radius bound, while the simulated legs, columns
and platform stay found within 2 points (`make accuracy`).
Units: metres and degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..base.bounds import D_MAX, NO_SENSE, SHARE, Section, features_combined, param
from ..base.bounds import bound as _b
from .feature_layout import FEATURE_PARAMS

_EVERY_SMALL_SEGMENT = (
    "every single-line segment small enough to be a circle gets the HTC and keeps the better fit, whatever its "
    "extent and radius (docs/method.md §5.2)"
)


@dataclass(frozen=True)
class FeatureParams(Section):
    """The `[features]` table of a config file: parameters of `datmo segment` and `datmo features`."""

    name: ClassVar[str] = "features"
    removed: ClassVar[dict[str, str]] = {
        "leg_min_probability": "every cluster the leg detector scores above 0 is listed with its probability, and "
        "the leg threshold is the leg model's own (threshold_p)",
        "circle_check_extent": _EVERY_SMALL_SEGMENT,
        "circle_check_radius": _EVERY_SMALL_SEGMENT,
    }
    renamed: ClassVar[dict[str, str]] = {
        "leg_radius_max": "column_radius_min (circles larger than it are column candidates; the largest leg is "
        "[track] leg_radius_max)"
    }

    # segmentation (docs/method.md §4)
    c0: float = param(
        0.08,
        _b(0, 5, "m", "0: the angular term alone; metres of gap would join everything"),
        "Segmentation threshold C0 of C0 + C1·min(r_i, r_i+1), C1 from the scan's angle step.",
    )
    min_points: int = param(
        3,
        _b(1, 10_000, "beams", "more than any scanner has in a scan", integer=True),
        "Drop segments with fewer points (the paper's 5 loses legs beyond 4 m; 3 keeps them to 6 m).",
    )
    # lines, HTL (section 5.1)
    theta_resolution: float = param(
        1.5,
        _b(0.1, 10, "degrees", "finer cells only grow the line accumulator (the fit refines)"),
        "HTL theta cell (the least-squares fit refines the angle).",
    )
    rho_resolution: float = param(
        0.02, _b(0.001, 1, "m", "below 1 mm the line accumulator outgrows memory"), "HTL rho cell."
    )
    vote_window: float = param(
        10.0,
        _b(1, 90, "degrees", "90: a point votes for every direction"),
        "A point votes for the directions this near its local normal (90: all).",
    )
    line_min_points: int = param(4, _b(1, 10_000, "points", integer=True), "A line has at least this many points.")
    line_min_racc: float = param(
        0.5, _b(0, 1, "", "r_acc is a share of the segment's points", open_=True), "... and r_acc above this."
    )
    line_min_length: float = param(0.10, _b(0, 100, "m", NO_SENSE, open_=True), "... and is longer than this.")
    perpendicular_tolerance: float = param(
        15.0,
        _b(0, 45, "degrees", "beyond 45° any two lines would be perpendicular"),
        "Two lines within this of 90° are perpendicular.",
    )
    # circles, HTC (section 5.1)
    circle_radius_min: float = param(
        0.05, _b(0, 2, "m", "circles are legs, posts and columns", open_=True), "Smallest HTC radius."
    )
    circle_radius_max: float = param(
        0.40, _b(0, 5, "m", "circles are legs, posts and columns", open_=True), "Largest HTC radius."
    )
    circle_radius_step: float = param(
        0.04,
        _b(0.001, 1, "m", "each radius is a pass of the circle transform"),
        "HTC radii voted for, 2 tolerances apart (the fit refines).",
    )
    circle_cell: float = param(
        0.01,
        _b(0.001, 0.5, "m", "finer cells only grow the circle accumulator (the fit refines)"),
        "HTC (a, b) cell size.",
    )
    circle_window: float = param(
        0.04,
        _b(0, 0.5, "m", "the centre estimate is off by centimetres, not metres", open_=True),
        "Votes within this of the P_ini/P_near/P_end centre estimate.",
    )
    circle_tolerance: float = param(
        0.02,
        _b(0, 1, "m", "a ring wider than a metre is no circle", open_=True),
        "A point votes for a centre when | |p - c| - r | is at most this.",
    )
    circle_min_points: int = param(3, _b(1, 10_000, "points", integer=True), "A circle has at least this many points.")
    circle_min_sagitta: float = param(
        0.02, _b(0, 1, "m", open_=True), "An arc bulges this much towards the scanner (P_near against the chord)."
    )
    # a circle must be a well-posed arc (0 turns a test off):
    circle_min_coverage: float = param(
        0.6,
        _b(0, 1, "", SHARE + "; 0 turns the test off"),
        "A circle's points are at least this share of the beams its near side spans, 2 asin(r/d)/step.",
    )
    circle_residual_ratio: float = param(
        0.8, _b(0, 100, "", "0 turns the test off"), "A circle fit's rms residual is at most this times the line fit's."
    )
    circle_radius_margin: float = param(
        0.01, _b(0, 1, "m", "0 turns the test off"), "A circle's radius is more than this inside the HTC radius range."
    )
    circle_lines_ratio: float = param(
        1.0,
        _b(0, 100, "", "0 turns the test off"),
        "... and its residual at most this times the segment's HTL lines' (two or more: a corner).",
    )
    # landmarks (section 6.2)
    d_max: float = param(
        1.5,
        D_MAX,
        "Lines and objects larger than this are static (walls): the paper's d_max, for landmarks and tracking alike.",
    )
    corner_gap: float = param(
        0.3, _b(0, 10, "m", open_=True), "Two wall lines meet when their ends are this close to the junction."
    )
    deflection_min: float = param(10.0, _b(0, 90, "degrees"), "Smaller turns between wall lines are no deflections.")
    column_radius_min: float = param(
        0.13, _b(0, 2, "m", open_=True), "Circles larger than this are no legs: column candidates."
    )
    bench_min_length: float = param(0.6, _b(0, 10, "m", open_=True), "Shortest span between a bench's supports.")
    bench_max_length: float = param(2.5, _b(0, 20, "m", open_=True), "Longest span between a bench's supports.")
    landmark_match: float = param(
        0.3, _b(0, 10, "m", open_=True), "A detection within this of a landmark is that landmark."
    )
    landmark_min_count: int = param(
        3, _b(1, 1_000_000, "scans", integer=True), "Scans a landmark is seen in before it enters the database."
    )
    column_max_drift: float = param(
        0.1, _b(0, 10, "m", open_=True), "A column candidate that moves more than this is no column."
    )
    column_min_time: float = param(
        3.0, _b(0, 86_400, "s", "a day", open_=True), "A column is seen in place at least this long."
    )
    # legs: the learned leg detector
    leg_model: str = param(
        "default",
        help="Leg detector: 'default' (the model shipped with datmo), a model file "
        "from datmo train-legs, or 'paper' (no detector: legs by the paper's "
        "circle rule and walking pattern).",
        metavar="MODEL",
    )

    @classmethod
    def combined(cls, params: FeatureParams, where: str) -> None:
        features_combined(params, where)

    def kernel_vector(self) -> np.ndarray:
        """The parameters as the feature kernels read them: one float64 vector indexed by feature_layout.FP_* (in
        the order of feature_layout.FEATURE_PARAMS; units as the fields, but radians for the keys in degrees)."""
        return np.array(
            [
                np.radians(getattr(self, key)) if conversion == "radians" else getattr(self, key)
                for key, conversion in FEATURE_PARAMS
            ],
            np.float64,
        )
