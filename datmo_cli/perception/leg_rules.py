"""The leg detector's vocabulary: the names and order of its segment features (the columns leg_features.py
computes and a leg model's trees split on), the clips of those features, leg_tracker's gap clusters and the
candidate rule (a segment too small or too wide is never a leg). Metres and radians, sensor frame."""

from __future__ import annotations

FEATURE_NAMES: tuple[str, ...] = (
    "n_points",  # valid returns in the segment
    "width",  # m, first to last point
    "linearity",  # m, RMS orthogonal residual of the total-least-squares line
    "circularity",  # m, RMS radial residual of the algebraic (Kasa) circle; = linearity if collinear
    "radius",  # m, that circle's radius, clipped to RADIUS_CLIP (also when collinear)
    "std",  # m, sqrt(sum |p - centroid|^2 / (n - 1))
    "median_deviation",  # m, mean |p - median point| (component-wise median)
    "boundary_length",  # m, sum of consecutive point distances
    "boundary_regularity",  # m, standard deviation of consecutive point distances
    "mean_curvature",  # 1/m, mean over interior triples of 1/circumradius, + when bulging toward the sensor
    "mean_inscribed_angle",  # rad, mean angle at interior points between the first and last point (pi: a line)
    "inscribed_angle_std",  # rad, standard deviation of those angles
    "distance",  # m, range of the centroid
    "subtended_angle",  # rad, |angle of last point's beam - angle of first point's beam|
    "occluded_start",  # 1.0 when the beam before the first point is a valid return nearer by > margin
    "occluded_end",  # 1.0 when the beam after the last point is a valid return nearer by > margin
    "jump_start",  # m, range of the nearest valid return before the first point minus the first
    # point's (+ when that return lies behind), clipped to +-JUMP_CLIP; +JUMP_CLIP: none
    "jump_end",  # m, the same beyond the last point
    "neighbour_distance",  # m, centroid to the nearest other candidate's centroid in the scan, <= NEIGHBOUR_CLIP
    "density",  # n_points * angle step * distance / width (~1 for a surface facing the sensor),
    # <= DENSITY_CLIP (also for zero width): independent of the scanner's resolution
    "relative_curvature",  # mean_curvature * width: scale-free (2 for a half circle)
)
RADIUS_CLIP = 1.0  # m: the radius feature's bound (degenerate or nearly straight segments)
JUMP_CLIP = 3.0  # m (the kernels' constants, repeated here for readers)
NEIGHBOUR_CLIP = 2.0  # m
DENSITY_CLIP = 10.0
GAP_M = 0.13  # m: leg_tracker's cluster gap (gap_clusters)
GAP_MIN_POINTS = 3
OCCLUSION_MARGIN = 0.1  # m
CANDIDATE_MAX_WIDTH = 0.8  # m
CANDIDATE_MIN_POINTS = 3
