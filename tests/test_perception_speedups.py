"""The exact shortcuts of the faster perception kernels, each against a slow reference:
HTC skips radii that cannot take the peak or beat the lines, the normal's angle is wrapped without fmod,
each scan's rows are gathered from its own stretch, HTC's ring count calls hypot only near the ring's bounds,
the corner test computes each line's cos and sin once, and a run's blocks share their row buffers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.perception import feature_layout as FL
from datmo_cli.perception import hough_circles as HC
from datmo_cli.perception import hough_lines as HL
from datmo_cli.perception import scan_extractor as SX
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.unit

PVEC = FeatureParams().kernel_vector()


def kernel_circle(x, y, beat=-1.0) -> np.ndarray:
    x = np.ascontiguousarray(x, np.float64)
    y = np.ascontiguousarray(y, np.float64)
    w = int(round(PVEC[FL.FP_CIRCLE_WINDOW] / PVEC[FL.FP_CIRCLE_CELL]))
    out = np.zeros(5)
    HC.circle_of_run(
        x, y, 0, len(x), PVEC, np.zeros((2 * w + 1, 2 * w + 1), np.int32), np.empty(len(x), np.int64), out, beat
    )
    return out


def reference_votes(x, y) -> int:
    p = PVEC
    w = int(round(p[FL.FP_CIRCLE_WINDOW] / p[FL.FP_CIRCLE_CELL]))
    return ref.htc_peak(
        list(x),
        list(y),
        p[FL.FP_CIRCLE_RADIUS_MIN],
        p[FL.FP_CIRCLE_RADIUS_MAX],
        p[FL.FP_CIRCLE_RADIUS_STEP],
        w,
        p[FL.FP_CIRCLE_CELL],
        p[FL.FP_CIRCLE_TOLERANCE],
        p[FL.FP_CIRCLE_MIN_SAGITTA],
    )


INC = math.radians(0.5)


def noisy_arc(radius, dist, bearing, sigma, seed, span=0.5, inc=INC):
    """Points of a circle of `radius` at `dist` and `bearing` seen from the origin, within `span` rad of its
    bearing, with Gaussian range noise `sigma` (m)."""
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    angles = np.arange(bearing - span, bearing + span, inc)
    r = ref.ray_circle(angles, cx, cy, radius)
    ok = np.isfinite(r)
    r = r[ok] + np.random.default_rng(seed).normal(0, sigma, int(ok.sum()))
    return ref.points(r, angles[ok])


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.06, 0.38),
    st.floats(0.6, 4.0),
    st.floats(-1.5, 1.5),
    st.sampled_from([0.0, 0.004, 0.015, 0.04]),
    st.integers(0, 2**31),
    st.sampled_from([-1.0, 0.3, 0.5, 0.8, 0.95]),
)
def test_htc_peak_equals_the_full_vote_and_beat_only_drops_circles_it_could_not_keep(
    radius, dist, bearing, sigma, seed, beat
):
    """Radii whose points cannot reach the peak so far, or r_acc above `beat`, are not voted: the peak of
    every radius voted in full (the reference) is the kernel's, and with `beat` the kernel returns the very
    same circle when its r_acc is above `beat`, none otherwise."""
    x, y = noisy_arc(radius, dist, bearing, sigma, seed)
    if len(x) < 3:
        return
    full = kernel_circle(x, y)
    assert round(full[4] * len(x)) == reference_votes(x, y)
    out = kernel_circle(x, y, beat)
    if full[4] > beat:
        assert np.array_equal(out, full)
    else:
        assert out[0] == 0.0


def test_a_beat_of_one_or_more_skips_the_vote():
    x, y = noisy_arc(0.1, 1.5, 0.2, 0.0, 0)
    assert kernel_circle(x, y)[4] == 1.0
    assert kernel_circle(x, y, 1.0)[0] == 0.0


@settings(max_examples=200, deadline=None)
@given(st.floats(-math.pi, 2 * math.pi, exclude_max=True))
def test_wrap_pi_is_the_float_modulo(a):
    expected = a % math.pi
    got = HL._wrap_pi(a)
    if a == 0.0:  # -0.0 stays -0.0 where the modulo gives 0.0: the same theta cell
        assert got == expected
    else:
        assert got == expected and math.copysign(1.0, got) == math.copysign(1.0, expected)


def test_wrap_pi_edges():
    for a in (
        -math.pi,
        -1e-300,
        -1e-17,
        0.0,
        math.pi,
        math.nextafter(math.pi, 0),
        3 * math.pi / 2,
        math.nextafter(2 * math.pi, 0),
    ):
        assert HL._wrap_pi(a) == a % math.pi, a


def test_gather_rows_keeps_each_scans_rows_in_order():
    B = 4
    rows = np.arange(3 * B * 2, dtype=np.float64).reshape(3 * B, 2)
    counts = np.array([[2, 0], [0, 1], [3, 4]], np.int64)
    out = np.empty((5, 2))
    SX.gather_rows(rows, counts, 0, B, out)
    expected = np.concatenate([rows[0:2], rows[2 * B : 2 * B + 3]])
    assert np.array_equal(out, expected)
    out = np.empty((5, 2))
    SX.gather_rows(rows, counts, 1, B, out)
    assert np.array_equal(out, np.concatenate([rows[B : B + 1], rows[2 * B : 3 * B]]))


def reference_ring_count(x, y, s, e, ca, cb, d_lo, d_hi) -> int:
    """The points of [s, e) whose np.hypot distance to (ca, cb) lies in [d_lo, d_hi], tested one by one."""
    return sum(1 for i in range(s, e) if d_lo <= np.hypot(x[i] - ca, y[i] - cb) <= d_hi)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.floats(-0.3, 0.5),
    st.floats(0.0, 0.6),
    st.integers(0, 39),
    st.integers(0, 39),
)
def test_ring_count_equals_hypot_on_every_point(seed, d_lo, width, on_lo, on_hi):
    rng = np.random.default_rng(seed)
    n = 40
    ca, cb = rng.uniform(-5, 5, 2)
    x = ca + rng.uniform(-0.8, 0.8, n)
    y = cb + rng.uniform(-0.8, 0.8, n)
    d_hi = d_lo + width
    # bounds exactly at a point's hypot, and one ulp either side: the inclusive tests must hold to the bit
    for lo, hi in (
        (d_lo, d_hi),
        (float(np.hypot(x[on_lo] - ca, y[on_lo] - cb)), float(np.hypot(x[on_hi] - ca, y[on_hi] - cb))),
        (math.nextafter(float(np.hypot(x[on_lo] - ca, y[on_lo] - cb)), 1.0), d_hi),
        (d_lo, math.nextafter(float(np.hypot(x[on_hi] - ca, y[on_hi] - cb)), -1.0)),
    ):
        for s, e in ((0, n), (3, 17), (5, 5)):
            assert HC.ring_count(x, y, s, e, ca, cb, lo, hi) == reference_ring_count(x, y, s, e, ca, cb, lo, hi)


def test_ring_count_bounds_at_or_below_zero():
    x = np.array([1.0, 1.0, 2.0])
    y = np.array([2.0, 2.0, 2.0])
    for lo, hi in ((-1.0, 0.0), (0.0, 0.0), (-1.0, -0.5), (-0.5, 1.0), (0.0, 1.0)):
        assert HC.ring_count(x, y, 0, 3, 1.0, 2.0, lo, hi) == reference_ring_count(x, y, 0, 3, 1.0, 2.0, lo, hi)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(1, 30))
def test_lines_rss_equals_the_per_point_sum(seed, ncand, m):
    rng = np.random.default_rng(seed)
    cand = np.zeros((10, 12))
    cand[:, FL.LC_THETA] = rng.uniform(0, np.pi, 10)
    cand[:, FL.LC_RHO] = rng.uniform(-3, 3, 10)
    cidx = rng.permutation(10)[:ncand].astype(np.int64)
    x = rng.uniform(-4, 4, 50)
    y = rng.uniform(-4, 4, 50)
    idx = rng.choice(50, m, replace=False).astype(np.int64)
    expected = 0.0
    for i in idx:
        dmin = min(
            abs(x[i] * np.cos(cand[j, FL.LC_THETA]) + y[i] * np.sin(cand[j, FL.LC_THETA]) - cand[j, FL.LC_RHO])
            for j in cidx
        )
        expected += dmin * dmin
    assert SX._lines_rss(x, y, idx, m, cand, cidx, ncand, np.empty(2 * ncand)) == pytest.approx(expected, rel=1e-12)


def test_blocks_sharing_row_buffers_give_each_block_its_own_rows():
    from datmo_cli.logs import mcapio
    from datmo_cli.logs.scan import ScanRun
    from datmo_cli.perception import features

    small = mcapio.read_run(features_sample())
    # a dense first block, then scans with fewer features (far returns cut): stale rows must not show
    ranges = np.concatenate(
        [small.ranges[: features.BLOCK], np.where(small.ranges[:40] > 1.5, np.inf, small.ranges[:40])]
    )
    stamps = np.arange(len(ranges), dtype=np.int64) * 10**8
    whole = features.extract_run(ScanRun(stamps, ranges, small.geometry), landmarks=False)
    tail = features.extract_run(
        ScanRun(stamps[features.BLOCK :], ranges[features.BLOCK :], small.geometry), landmarks=False
    )
    for name in ("lines", "circles", "blobs"):
        rows, offsets = getattr(whole, name), getattr(whole, name[:-1] + "_offsets")
        t_rows, t_offsets = getattr(tail, name), getattr(tail, name[:-1] + "_offsets")
        assert np.array_equal(rows[offsets[features.BLOCK] :], t_rows)
        assert np.array_equal(offsets[features.BLOCK :] - offsets[features.BLOCK], t_offsets)
    assert np.array_equal(whole.seg_start[whole.seg_offsets[features.BLOCK] :], tail.seg_start)


def features_sample():
    from conftest import SAMPLE_LOGS

    return SAMPLE_LOGS / "hall.mcap"
