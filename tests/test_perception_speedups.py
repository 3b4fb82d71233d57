"""The exact shortcuts of the faster perception kernels, each against a slow reference:
HTC skips radii that cannot take the peak or beat the lines, the normal's angle is wrapped without fmod, and
each scan's rows are gathered from its own stretch."""

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
    w = int(round(PVEC[FL.P_CWINDOW] / PVEC[FL.P_CELL]))
    out = np.zeros(5)
    HC.circle_of_run(
        x, y, 0, len(x), PVEC, np.zeros((2 * w + 1, 2 * w + 1), np.int32), np.empty(len(x), np.int64), out, beat
    )
    return out


def reference_votes(x, y) -> int:
    p = PVEC
    w = int(round(p[FL.P_CWINDOW] / p[FL.P_CELL]))
    return ref.htc_peak(
        list(x), list(y), p[FL.P_R_MIN], p[FL.P_R_MAX], p[FL.P_R_STEP], w, p[FL.P_CELL], p[FL.P_CTOL], p[FL.P_MIN_SAG]
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
