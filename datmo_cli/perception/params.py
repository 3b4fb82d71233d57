"""Parameters of `datmo segment` and `datmo features` (the `[features]` table of a config file).

Defaults follow Castro, Nunes and Ruano (2004) as restated in method.md where the paper gives a value
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

from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from ..bounds import FEATURES, check, features_combined
from ..errors import ConfigError


@dataclass(frozen=True)
class FeatureParams:
    # segmentation (method.md section 4)
    c0: float = 0.08                 # m; threshold C0 + C1 * min(r_i, r_i+1), C1 from the scan's angle step
    min_points: int = 3              # segments with fewer points are dropped (paper: 5; 3 keeps legs to 6 m)
    # lines, HTL (section 5.1)
    theta_resolution: float = 1.5    # degrees per theta cell (the least-squares fit refines the angle)
    rho_resolution: float = 0.02     # m per rho cell
    vote_window: float = 10.0        # degrees either side of a point's local normal that it votes for (90: all)
    line_min_points: int = 4         # a line has more than 3 points
    line_min_racc: float = 0.5       # and r_acc above this
    line_min_length: float = 0.10    # and is longer than this, m
    perpendicular_tolerance: float = 15.0   # degrees from 90 within which two lines are perpendicular
    # circles, HTC (section 5.1)
    circle_radius_min: float = 0.05  # m
    circle_radius_max: float = 0.40  # m
    circle_radius_step: float = 0.04  # m; radii voted for, 2 tolerances apart (the fit refines)
    circle_cell: float = 0.01        # m; (a, b) cell size
    circle_window: float = 0.04      # m; votes within this of the P_ini/P_near/P_end estimate
    circle_tolerance: float = 0.02   # m; a point votes for a centre when | |p - c| - r | <= this
    circle_min_points: int = 3
    circle_check_extent: float = 0.35   # m; a one-line segment shorter than this also gets HTC (legs) ...
    circle_check_radius: float = 0.15   # m; ... and is a circle only with a radius up to this
    circle_min_sagitta: float = 0.02    # m; an arc must bulge this much towards the scanner (P_near vs chord)
    # a circle must be a well-posed arc (0 turns a test off):
    circle_min_coverage: float = 0.6    # points >= this share of the beams its near side spans, 2 asin(r/d)/step
    circle_residual_ratio: float = 0.8  # circle fit's rms residual <= this times the line fit's, same points
    circle_radius_margin: float = 0.01  # m; radius more than this inside [radius_min, radius_max] (not pinned)
    circle_lines_ratio: float = 1.0     # and <= this times the segment's HTL lines' (two or more: a corner)
    # landmarks (section 6.2)
    d_max: float = 1.5               # m; lines longer than this are static (walls)
    corner_gap: float = 0.3          # m; two wall lines meet when their ends are this close to the junction
    deflection_min: float = 10.0     # degrees; smaller turns between wall lines are not deflections
    leg_radius_max: float = 0.13     # m; circles larger than this cannot be legs (column candidates)
    bench_min_length: float = 0.6    # m; between a bench's two supports
    bench_max_length: float = 2.5    # m
    landmark_match: float = 0.3      # m; a detection within this of a landmark is the same landmark
    landmark_min_count: int = 3      # scans a landmark is seen in before it enters the database
    column_max_drift: float = 0.1    # m; a column candidate that moves more than this is not a column
    column_min_time: float = 3.0     # s; a column is seen in place at least this long
    # legs: the learned leg detector ("default": the model shipped in the package), a model file from
    # `datmo train-legs`, or "paper": no detector, legs by the paper's circle rule in tracking
    leg_model: str = "default"
    leg_min_probability: float = 0.2   # segments with at least this leg probability are listed as legs

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **changes) -> FeatureParams:
        """A copy with `changes` (keys checked; None values ignored)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        return from_dict({**self.to_dict(), **changes})

    def kernel_vector(self) -> np.ndarray:
        """The parameters in the order `_kernels` reads them (radians where the kernels need them)."""
        return np.array([self.c0, self.min_points, np.radians(self.theta_resolution), self.rho_resolution,
                         np.radians(self.vote_window), self.line_min_points, self.line_min_racc,
                         self.line_min_length, np.radians(self.perpendicular_tolerance), self.circle_radius_min,
                         self.circle_radius_max, self.circle_radius_step, self.circle_cell, self.circle_window,
                         self.circle_tolerance, self.circle_min_points, self.circle_check_extent,
                         self.circle_min_sagitta, self.circle_check_radius, self.circle_min_coverage,
                         self.circle_residual_ratio, self.circle_radius_margin, self.circle_lines_ratio], np.float64)


_STRINGS = {"leg_model"}


def from_dict(values: dict, where: str = "features") -> FeatureParams:
    """FeatureParams from a mapping, checking names, types and ranges (bounds.FEATURES); ConfigError names the
    key, the value and the allowed range."""
    known = {f.name for f in fields(FeatureParams)}
    out = {}
    for key, value in values.items():
        if key not in known:
            raise ConfigError(f"{where}.{key}: unknown parameter (known: {', '.join(sorted(known))})")
        if key in _STRINGS:
            if not isinstance(value, str) or not value.strip():
                raise ConfigError(f"{where}.{key}: must be a non-empty string, got {value!r}")
            out[key] = value
        else:
            out[key] = check(FEATURES[key], value, f"{where}.{key}")
    params = FeatureParams(**{**asdict(FeatureParams()), **out})
    features_combined(params, where)
    return params


def load_toml(path: str | Path) -> FeatureParams:
    """Parameters from the `[features]` table of a TOML file (or its top level when it has no such table)."""
    from ..config import read_table

    return from_dict(read_table(path, "features"), where=f"{path}: features")
