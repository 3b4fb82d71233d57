"""Robustness of segmentation and feature extraction (hypothesis): all-NaN scans, one-beam scans, zero and
huge ranges, every beam equal, random mixtures, any angle step and beam count. Never a crash, and the
output always keeps its invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datmo_cli.errors import InputError
from datmo_cli.log.scan import ScanGeometry, ScanRun
from datmo_cli.perception.features import extract_run, segment_run
from datmo_cli.perception.params import FeatureParams

SPECIAL = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1e6, 8.0, 0.02])


def run_of(ranges: np.ndarray, inc: float, range_max: float = 8.0) -> ScanRun:
    n, b = ranges.shape
    g = ScanGeometry(-inc * (b - 1) / 2, inc, b, 0.0, range_max, 0.0, 0.2, "laser")
    return ScanRun(np.arange(n, dtype=np.int64) * 100_000_000, ranges.astype(np.float32), g)


@st.composite
def scans(draw):
    beams = draw(st.sampled_from([1, 2, 3, 181, 361, 768]))
    n = draw(st.integers(1, 4))
    kind = draw(st.sampled_from(["random", "special", "equal", "room"]))
    if kind == "random":
        r = draw(arrays(np.float32, (n, beams), elements=st.one_of(st.floats(0, 10, width=32), SPECIAL)))
    elif kind == "special":
        r = np.full((n, beams), draw(SPECIAL), np.float32)
    elif kind == "equal":
        r = np.full((n, beams), draw(st.floats(0.01, 7.9)), np.float32)
    else:
        seed = draw(st.integers(0, 2**31))
        rng = np.random.default_rng(seed)
        a = np.linspace(0, 2 * np.pi, beams)
        r = (3 + np.sin(3 * a)[None, :] + rng.normal(0, 0.01, (n, beams))).astype(np.float32)
        r[rng.random(r.shape) < 0.05] = np.nan
    inc = math.radians(draw(st.sampled_from([0.25, 0.5, 1.0, 0.352])))
    return r, inc


def check_invariants(f, n_scans: int, n_beams: int, min_points: int) -> None:
    for off in (f.seg_offsets, f.line_offsets, f.circle_offsets, f.blob_offsets):
        assert len(off) == n_scans + 1 and off[0] == 0 and np.all(np.diff(off) >= 0)
    assert f.seg_offsets[-1] == len(f.seg_start)
    assert f.line_offsets[-1] == len(f.lines) and f.circle_offsets[-1] == len(f.circles)
    assert f.blob_offsets[-1] == len(f.blobs)
    assert np.all(f.seg_end.astype(int) - f.seg_start.astype(int) >= min_points)
    assert np.all(f.seg_end <= n_beams)
    for items, offsets in ((f.lines, f.line_offsets), (f.circles, f.circle_offsets), (f.blobs, f.blob_offsets)):
        for k in range(n_scans):
            seg = items[offsets[k]:offsets[k + 1]]
            nseg = f.seg_offsets[k + 1] - f.seg_offsets[k]
            assert np.all(seg["segment"] < nseg)
            g = f.seg_offsets[k] + seg["segment"].astype(np.int64)
            assert np.all(seg["first"] >= f.seg_start[g]) and np.all(seg["last"] < f.seg_end[g])
            assert np.all(seg["first"] <= seg["last"])
        for name in items.dtype.names:
            if items.dtype[name].kind == "f":
                assert np.all(np.isfinite(items[name])), name
    lines = f.lines
    assert np.all(lines["n_points"] > 3) and np.all(lines["r_acc"] > 0.5) and np.all(lines["length"] > 0.1)
    assert np.all(lines["theta"] >= 0) and np.all(lines["theta"] < np.pi + 1e-6)
    assert np.all(f.circles["radius"] > 0) and np.all(f.circles["r_acc"] > 0.5)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scans(), st.integers(1, 6))
def test_features_never_crash_and_keep_their_invariants(scan, min_points):
    r, inc = scan
    run = run_of(r, inc)
    params = FeatureParams(min_points=min_points)
    f = extract_run(run, params)
    check_invariants(f, *r.shape, min_points)
    start, end, offsets = segment_run(run, params)
    assert np.array_equal(start, f.seg_start) and np.array_equal(end, f.seg_end)
    assert np.array_equal(offsets, f.seg_offsets)


@pytest.mark.parametrize("value", [np.nan, np.inf, 0.0, 1e6])
def test_scans_without_a_valid_return_have_nothing(value):
    f = extract_run(run_of(np.full((3, 361), value, np.float32), math.radians(0.5)))
    assert len(f.seg_start) == len(f.lines) == len(f.circles) == len(f.blobs) == 0
    assert len(f.landmarks.final()) == 0


def test_an_empty_run_and_a_zero_step_are_handled():
    f = extract_run(run_of(np.zeros((0, 361), np.float32), math.radians(0.5)))
    assert len(f) == 0 and f.seg_offsets.tolist() == [0]
    with pytest.raises(InputError):
        extract_run(run_of(np.full((1, 10), 2.0, np.float32), 0.0))


def test_given_segments_out_of_range_are_clipped_not_trusted():
    run = run_of(np.full((1, 50), 2.0, np.float32), math.radians(0.5))
    seg = (np.array([-5, 40]), np.array([30, 500]), np.array([0, 2]))
    f = extract_run(run, segments=seg)
    check_invariants(f, 1, 50, 1)
