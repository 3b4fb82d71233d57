"""The leg detector's segment features (numba) against known geometry and the plain-numpy reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.perception import leg_features as LF
from datmo_cli.perception import legs
from datmo_cli.perception.features import segment_run
from datmo_cli.perception.leg_model import LegModel
from datmo_cli.perception.legs import FEATURE_NAMES, RADIUS_CLIP, candidate_mask, cluster_features

pytestmark = pytest.mark.unit

COL = {name: i for i, name in enumerate(FEATURE_NAMES)}
ANGLES_361 = np.radians(np.linspace(-90.0, 90.0, 361))


def circle_ranges(angles: np.ndarray, cx: float, cy: float, radius: float) -> np.ndarray:
    """Ranges (m) of beams at angles hitting a circle (centre cx, cy, m); +inf where they miss."""
    c, s = np.cos(angles), np.sin(angles)
    along = c * cx + s * cy
    disc = along**2 - (cx * cx + cy * cy - radius**2)
    with np.errstate(invalid="ignore"):
        r = along - np.sqrt(disc)
    return np.where(disc > 0, r, np.inf).astype(np.float32)


def features_of(ranges: np.ndarray, segments: list[tuple[int, int]], angles=None, lo=0.0, hi=30.0):
    angles = np.radians(np.linspace(-90.0, 90.0, len(ranges))) if angles is None else angles
    starts = np.array([s for s, _ in segments], np.int64)
    ends = np.array([e for _, e in segments], np.int64)
    return cluster_features(ranges[None, :], angles, starts, ends, [0, len(segments)], lo, hi)


def test_circle_of_known_radius():
    r = circle_ranges(ANGLES_361, 1.5, 0.2, 0.06)
    hit = np.flatnonzero(np.isfinite(r))
    f = features_of(r, [(hit[0], hit[-1] + 1)])[0]
    assert f[COL["n_points"]] == len(hit) >= 3
    assert f[COL["radius"]] == pytest.approx(0.06, abs=1e-4)
    assert f[COL["circularity"]] < 1e-5
    assert f[COL["mean_curvature"]] == pytest.approx(1 / 0.06, rel=0.05)  # convex toward the sensor: positive
    assert f[COL["distance"]] == pytest.approx(math.hypot(1.5, 0.2) - 0.06, abs=0.03)
    assert f[COL["occluded_start"]] == f[COL["occluded_end"]] == 0.0


def test_hollow_circle_has_negative_curvature():
    # the inside of a round room around the sensor, seen off-centre: concave, so the curvature is negative
    angles = np.radians(np.linspace(-20.0, 20.0, 41))
    r = (np.sqrt(3.0**2 - (0.5 * np.sin(angles)) ** 2) + 0.5 * np.cos(angles)).astype(np.float32)
    f = features_of(r, [(0, 41)], angles)[0]
    assert f[COL["radius"]] == RADIUS_CLIP
    assert f[COL["circularity"]] < 1e-5
    assert f[COL["mean_curvature"]] == pytest.approx(-1 / 3.0, rel=0.05)


def test_straight_wall():
    angles = np.radians(np.linspace(-30.0, 30.0, 121))
    r = (2.0 / np.cos(angles)).astype(np.float32)
    f = features_of(r, [(0, 121)], angles)[0]
    assert f[COL["linearity"]] < 1e-6
    assert f[COL["radius"]] == RADIUS_CLIP
    assert f[COL["circularity"]] < 1e-3
    assert f[COL["width"]] == pytest.approx(2 * 2.0 * math.tan(math.radians(30.0)), rel=1e-5)
    assert f[COL["mean_inscribed_angle"]] == pytest.approx(math.pi, abs=1e-3)
    assert abs(f[COL["mean_curvature"]]) < 0.05
    assert f[COL["boundary_length"]] == pytest.approx(f[COL["width"]], rel=1e-5)
    assert f[COL["subtended_angle"]] == pytest.approx(math.radians(60.0))


def test_occlusion_flags():
    r = np.full(20, 3.0, np.float32)
    r[4] = 1.0  # nearer than the segment's first point: occludes it
    r[15] = 2.95  # nearer, but by less than the margin
    f = features_of(r, [(5, 15)])[0]
    assert (f[COL["occluded_start"]], f[COL["occluded_end"]]) == (1.0, 0.0)
    r[15] = 1.0
    r[4] = np.inf  # no return: not an occluder
    f = features_of(r, [(5, 15)])[0]
    assert (f[COL["occluded_start"]], f[COL["occluded_end"]]) == (0.0, 1.0)
    r[4] = 5.0  # farther: background, not an occluder
    r[15] = 0.01  # below range_min: invalid
    f = features_of(r, [(5, 15)], lo=0.05)[0]
    assert (f[COL["occluded_start"]], f[COL["occluded_end"]]) == (0.0, 0.0)
    f = features_of(np.full(20, 3.0, np.float32), [(0, 20)])[0]  # beams out of the scan
    assert (f[COL["occluded_start"]], f[COL["occluded_end"]]) == (0.0, 0.0)


def test_small_and_empty_segments():
    r = np.array([np.nan, 2.0, 2.1, np.inf, 2.0], np.float32)
    f = features_of(r, [(0, 1), (1, 2), (2, 3), (4, 4), (1, 5)])
    assert np.all(f[0] == 0) and np.all(f[3] == 0)
    assert f[1, COL["n_points"]] == 1 and f[1, COL["radius"]] == RADIUS_CLIP
    assert f[4, COL["n_points"]] == 3
    assert np.all(np.isfinite(f))
    assert not candidate_mask(f)[:4].any()


def test_validation():
    r = np.ones((2, 10), np.float32)
    with pytest.raises(ValueError, match="seg_offsets"):
        cluster_features(r, np.zeros(10), [0], [5], [0, 1], 0.0, 10.0)
    with pytest.raises(ValueError, match="angles"):
        cluster_features(r, np.zeros(9), [0], [5], [0, 1, 1], 0.0, 10.0)
    with pytest.raises(ValueError, match="within"):
        cluster_features(r, np.zeros(10), [0], [11], [0, 1, 1], 0.0, 10.0)
    assert cluster_features(r, np.zeros(10), [], [], [0, 0, 0], 0.0, 10.0).shape == (0, len(FEATURE_NAMES))


def assert_matches_naive(ranges, angles, start, end, offsets, lo, hi):
    got = cluster_features(ranges, angles, start, end, offsets, lo, hi)
    want = ref.cluster_features(ranges, angles, start, end, offsets, lo, hi)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


@st.composite
def scans(draw):
    B = draw(st.integers(3, 40))
    N = draw(st.integers(1, 3))
    value = st.one_of(st.floats(0.0625, 6.0, width=32), st.sampled_from([np.inf, np.nan, 0.0, 0.02, 10.0]))
    ranges = np.array(draw(st.lists(st.lists(value, min_size=B, max_size=B), min_size=N, max_size=N)), np.float32)
    step = draw(st.sampled_from([0.25, 0.5, 1.0, -0.5]))
    angles = np.radians(-45.0 + step * np.arange(B))
    starts, ends, offsets = [], [], [0]
    for _ in range(N):
        cuts = sorted(draw(st.lists(st.integers(0, B), max_size=6)))
        for a, b in zip(cuts[::2], cuts[1::2], strict=False):
            starts.append(a)
            ends.append(b)
        offsets.append(len(starts))
    return ranges, angles, np.array(starts, np.int64), np.array(ends, np.int64), np.array(offsets), 0.03, 8.0


@settings(max_examples=50, deadline=None)
@given(scans())
def test_random_scans_match_naive(case):
    assert_matches_naive(*case)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.3, 5.0), st.floats(-1.0, 1.0), st.floats(0.03, 0.3), st.integers(0, 2**31))
def test_noisy_circles_match_naive(dist, bearing, radius, seed):
    rng = np.random.default_rng(seed)
    r = circle_ranges(ANGLES_361, dist * math.cos(bearing), dist * math.sin(bearing), radius)
    r = np.where(np.isfinite(r), r + rng.normal(0, 0.01, r.shape), 7.0).astype(np.float32)
    hit = np.flatnonzero(r < 7.0)
    if len(hit) == 0:
        return
    assert_matches_naive(
        r[None, :], ANGLES_361, np.array([hit[0], 0]), np.array([hit[-1] + 1, 361]), np.array([0, 2]), 0.0, 7.5
    )


def test_sample_log_matches_naive(sample_logs):
    from datmo_cli.logs.mcapio import read_log, run_from_log

    run = run_from_log(read_log(sample_logs / "hall.mcap", topics=["/scan"]))
    sub = run.ranges[:5]
    start, end, offsets = segment_run(type(run)(run.stamps[:5], sub, run.geometry))
    g = run.geometry
    assert_matches_naive(sub, g.angles(), start, end, offsets, g.range_min, g.range_max)


def test_kernel_constants_match_the_documented_ones():

    assert LF.N_FEATURES == len(FEATURE_NAMES)
    assert (LF.JUMP_CLIP, LF.NEIGHBOUR_CLIP, LF.DENSITY_CLIP) == (
        legs.JUMP_CLIP,
        legs.NEIGHBOUR_CLIP,
        legs.DENSITY_CLIP,
    )


def test_range_jumps_skip_invalid_returns():
    r = np.full(20, 3.0, np.float32)
    r[4] = np.inf
    r[3] = 4.5  # the nearest valid return before the segment: 1.5 m behind it
    r[15] = 1.0  # after it: 2 m in front
    f = features_of(r, [(5, 15)])[0]
    assert f[COL["jump_start"]] == pytest.approx(1.5)
    assert f[COL["jump_end"]] == pytest.approx(-2.0)
    r[15:] = np.nan  # no valid return beyond the end
    r[0] = 9.0  # far behind: clipped
    r[1:5] = np.inf
    f = features_of(r, [(5, 15)])[0]
    assert (f[COL["jump_start"]], f[COL["jump_end"]]) == (legs.JUMP_CLIP, legs.JUMP_CLIP)


def test_neighbour_distance_and_density():
    angles = np.radians(np.linspace(-30.0, 30.0, 121))
    r = np.full(121, 4.0, np.float32)
    segs = [(10, 15), (17, 22), (100, 105), (40, 95)]  # two close blobs, a lone one, a wide wall (not a candidate)
    f = features_of(r, segs, angles)
    x = 4.0 * np.cos(angles)
    y = 4.0 * np.sin(angles)
    cent = [np.array([x[a:b].mean(), y[a:b].mean()]) for a, b in segs]
    d01 = np.linalg.norm(cent[0] - cent[1])
    assert f[0, COL["neighbour_distance"]] == pytest.approx(d01)
    assert f[1, COL["neighbour_distance"]] == pytest.approx(d01)
    assert f[2, COL["neighbour_distance"]] == legs.NEIGHBOUR_CLIP  # the wall is no candidate
    assert not candidate_mask(f)[3]
    assert f[3, COL["neighbour_distance"]] == pytest.approx(min(np.linalg.norm(cent[3] - c) for c in cent[:3]))
    # an arc of the circle around the sensor: n points span (n - 1) steps, so the density is n / (n - 1)
    assert f[0, COL["density"]] == pytest.approx(5 / 4, rel=1e-3)
    # a coarser scanner sees the same surface with fewer points and the same density
    g = features_of(r[::2].copy(), [(5, 8)], angles[::2].copy())[0]
    assert g[COL["density"]] == pytest.approx(3 / 2, rel=1e-3)


def test_relative_curvature_is_scale_free():
    for radius, dist in ((0.06, 1.0), (0.6, 10.0)):
        r = circle_ranges(ANGLES_361, dist, 0.0, radius)
        hit = np.flatnonzero(np.isfinite(r))
        f = features_of(r, [(hit[0], hit[-1] + 1)], hi=50.0)[0]
        assert f[COL["relative_curvature"]] == pytest.approx(f[COL["mean_curvature"]] * f[COL["width"]])
        assert 1.5 < f[COL["relative_curvature"]] < 2.2


def test_gap_clusters_known_scan():
    angles = np.radians(np.linspace(-10.0, 10.0, 21))
    r = np.full(21, 2.0, np.float32)
    r[5] = 3.0  # a jump of 1 m: ends the first cluster (beams 0..4), beam 5 alone is dropped
    r[12] = np.inf  # an invalid return ends the cluster of beams 6..11
    r[19] = 0.01  # below range_min; 13..18 form one cluster, beam 20 alone is dropped
    start, end, offsets = legs.gap_clusters(r[None, :], angles, 0.05, 30.0)
    assert start.tolist() == [0, 6, 13] and end.tolist() == [5, 12, 19] and offsets.tolist() == [0, 3]
    start, end, offsets = legs.gap_clusters(np.zeros((2, 21), np.float32), angles, 0.05, 30.0)
    assert len(start) == 0 and offsets.tolist() == [0, 0, 0]


@settings(max_examples=50, deadline=None)
@given(scans(), st.sampled_from([0.05, 0.13, 0.5]), st.integers(1, 4))
def test_gap_clusters_match_naive(case, gap, min_points):
    ranges, angles, *_, lo, hi = case
    got = legs.gap_clusters(ranges, angles, lo, hi, gap, min_points)
    want = ref.gap_clusters(ranges, angles, lo, hi, gap, min_points)
    for a, b in zip(got, want, strict=True):
        assert a.tolist() == b.tolist()
    assert_matches_naive(ranges, angles, *got, lo, hi)


def test_model_clusters_follow_the_provenance():
    r = np.full((1, 21), 2.0, np.float32)
    r[0, 10] = 3.0
    angles = np.radians(np.linspace(-10.0, 10.0, 21))
    segs = (np.array([0]), np.array([21]), np.array([0, 1]))

    def model(prov):
        return LegModel(
            np.array([-1]), np.zeros(1), np.array([-1]), np.array([-1]), np.ones(1), np.array([0]), provenance=prov
        )

    for m in (None, model({}), model({"clusters": {"method": "segments"}})):
        got = legs.model_clusters(r, angles, 0.0, 30.0, m, *segs)
        assert [a.tolist() for a in got] == [[0], [21], [0, 1]]
    got = legs.model_clusters(
        r, angles, 0.0, 30.0, model({"clusters": {"method": "gap", "gap": 0.13, "min_points": 3}}), *segs
    )
    assert [a.tolist() for a in got] == [[0, 11], [10, 21], [0, 2]]
    with pytest.raises(ValueError, match="cluster method"):
        legs.model_clusters(r, angles, 0.0, 30.0, model({"clusters": {"method": "dbscan"}}), *segs)
