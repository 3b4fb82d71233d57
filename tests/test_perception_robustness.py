"""Robustness of segment_run and extract_run (hypothesis): all-NaN scans, one-beam scans, zero and huge ranges,
every beam equal, random mixtures, 1, 0.5 and 0.25 degree steps, negative steps, beam counts 1 to 768. They
never crash, agree with each other and with the naive segmentation, and their output keeps its invariants.
Inputs that overflow the kernels' output buffers run in a subprocess, so memory corruption cannot take the
test session down."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datmo_cli.base.errors import InputError
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.perception.features import extract_run, segment_run
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent
SPECIAL = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -1.0, 1e6, 8.0, 7.999, 0.001])
STEPS_DEG = [1.0, 0.5, 0.25, -0.5, -1.0]


def run_of(ranges: np.ndarray, inc: float, range_max: float = 8.0, range_min: float = 0.0) -> ScanRun:
    n, b = ranges.shape
    g = ScanGeometry(
        angle_min=-inc * (b - 1) / 2,
        angle_increment=inc,
        n_beams=b,
        range_min=range_min,
        range_max=range_max,
        frame_id="laser",
    )
    return ScanRun(
        np.arange(n, dtype=np.int64) * 100_000_000, ranges.astype(np.float32), g, np.zeros((n, 0), np.float32)
    )


@st.composite
def scans(draw):
    beams = draw(st.sampled_from([1, 2, 3, 181, 361, 768]))
    n = draw(st.integers(1, 3))
    kind = draw(st.sampled_from(["random", "special", "equal", "scene", "scene"]))
    if kind == "random":
        r = draw(arrays(np.float32, (n, beams), elements=st.one_of(st.floats(0, 10, width=32), SPECIAL)))
    elif kind == "special":
        r = np.full((n, beams), draw(SPECIAL), np.float32)
    elif kind == "equal":
        r = np.full((n, beams), draw(st.floats(0.01, 7.99)), np.float32)
    else:  # walls, corners, arcs and clutter with noise and dropouts
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        a = np.linspace(0, 2 * np.pi, beams)
        r = 3 + np.sin(rng.integers(1, 6) * a)[None, :] * rng.uniform(0, 2) + rng.normal(0, 0.01, (n, beams))
        for _ in range(rng.integers(0, 6)):
            c = rng.integers(0, beams)
            w = rng.integers(1, 30)
            r[:, c : c + w] = rng.uniform(0.3, 7.5) + 0.1 * np.sin(np.linspace(0, np.pi, len(r[0, c : c + w])))
        r[rng.random(r.shape) < draw(st.sampled_from([0.0, 0.02, 0.3]))] = draw(SPECIAL)
        r = r.astype(np.float32)
    inc = math.radians(draw(st.sampled_from(STEPS_DEG)))
    return r, inc


def check_invariants(f, n_scans: int, n_beams: int, min_points: int) -> None:
    for off, items in (
        (f.seg_offsets, f.seg_start),
        (f.line_offsets, f.lines),
        (f.circle_offsets, f.circles),
        (f.blob_offsets, f.blobs),
    ):
        assert len(off) == n_scans + 1 and off[0] == 0 and off[-1] == len(items)
        assert np.all(np.diff(off) >= 0)
    assert len(f.seg_end) == len(f.seg_start) and len(f.stamps) == n_scans
    assert np.all(f.seg_end.astype(np.int64) - f.seg_start.astype(np.int64) >= min_points)
    assert np.all(f.seg_end <= n_beams)
    for k in range(n_scans):  # a scan's segments are ordered and disjoint
        s = f.seg_start[f.seg_offsets[k] : f.seg_offsets[k + 1]].astype(np.int64)
        e = f.seg_end[f.seg_offsets[k] : f.seg_offsets[k + 1]].astype(np.int64)
        assert np.all(s[1:] >= e[:-1])
    for items, offsets in ((f.lines, f.line_offsets), (f.circles, f.circle_offsets), (f.blobs, f.blob_offsets)):
        for k in range(n_scans):
            part = items[offsets[k] : offsets[k + 1]]
            nseg = f.seg_offsets[k + 1] - f.seg_offsets[k]
            assert np.all(part["segment"] < nseg)
            g = f.seg_offsets[k] + part["segment"].astype(np.int64)
            assert np.all(part["first"] >= f.seg_start[g]) and np.all(part["last"] < f.seg_end[g])
            assert np.all(part["first"] <= part["last"])
            if items is not f.lines:  # lines: see test_perception_kernels (line_of_run's idx reuse)
                assert np.all(part["n_points"] <= part["last"].astype(np.int64) - part["first"] + 1)
        for name in items.dtype.names:
            if items.dtype[name].kind == "f":
                assert np.all(np.isfinite(items[name])), name
    lines = f.lines
    assert np.all(lines["n_points"] > 3) and np.all(lines["r_acc"] > 0.5) and np.all(lines["length"] > 0.1)
    assert np.all(lines["r_acc"] <= 1.0 + 1e-6)
    assert np.all(lines["theta"] >= 0) and np.all(lines["theta"] < np.pi + 1e-6)
    c = f.circles
    assert np.all(c["radius"] > 0) and np.all(c["r_acc"] > 0.5) and np.all(c["r_acc"] <= 1.0 + 1e-6)
    assert np.all(c["n_points"] >= 3)
    b = f.blobs
    assert np.all(b["n_points"] == b["last"].astype(np.int64) - b["first"] + 1)
    assert np.all(b["size"] >= 0) and np.all(b["kind"] == (b["n_points"] < 3))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(scans(), st.integers(2, 6))
def test_extract_run_never_crashes_and_keeps_its_invariants(scan, min_points):
    r, inc = scan
    run = run_of(r, inc)
    params = FeatureParams(min_points=min_points)
    f = extract_run(run, params)
    check_invariants(f, *r.shape, min_points)
    start, end, offsets = segment_run(run, params)
    assert np.array_equal(start, f.seg_start) and np.array_equal(end, f.seg_end)
    assert np.array_equal(offsets, f.seg_offsets)
    # the segments are the naive reference's, scan by scan
    for k in range(len(r)):
        got = list(
            zip(start[offsets[k] : offsets[k + 1]].tolist(), end[offsets[k] : offsets[k + 1]].tolist(), strict=True)
        )
        assert got == ref.segment(r[k], inc, params.c0, 0.0, 8.0, min_points)
    # the landmark database is consistent with the scans
    snaps = f.landmarks.snap_offsets
    assert len(snaps) == len(r) + 1 and np.all(np.diff(snaps) >= 0)
    assert np.all(np.isfinite(f.landmarks.rows))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scans())
def test_given_segments_give_the_same_features(scan):
    """Features from a log's own segments (segment_run's) equal those computed in one pass."""
    r, inc = scan
    run = run_of(r, inc)
    f = extract_run(run, landmarks=False)
    g = extract_run(run, landmarks=False, segments=segment_run(run))
    for name in (
        "seg_start",
        "seg_end",
        "seg_offsets",
        "lines",
        "line_offsets",
        "circles",
        "circle_offsets",
        "blobs",
        "blob_offsets",
    ):
        assert np.array_equal(getattr(f, name), getattr(g, name)), name


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 0.0, -2.0, 1e6, 8.0])
@pytest.mark.parametrize("beams", [1, 2, 181, 361, 768])
def test_scans_without_a_valid_return_have_nothing(value, beams):
    f = extract_run(run_of(np.full((3, beams), value, np.float32), math.radians(0.5)))
    assert len(f.seg_start) == len(f.lines) == len(f.circles) == len(f.blobs) == 0
    assert f.seg_offsets.tolist() == f.line_offsets.tolist() == [0, 0, 0, 0]
    assert len(f.landmarks.final()) == 0


@pytest.mark.parametrize("beams", [1, 2, 4, 5, 181, 361, 768])
@pytest.mark.parametrize("step_deg", [1.0, 0.5, 0.25])
def test_all_beams_equal_is_one_arc_segment(beams, step_deg):
    """Every beam at 3 m: one segment (an arc about the scanner, concave: never a circle object)."""
    p = FeatureParams()
    f = extract_run(run_of(np.full((2, beams), 3.0, np.float32), math.radians(step_deg)), p)
    want = 1 if beams >= p.min_points else 0
    assert np.diff(f.seg_offsets).tolist() == [want, want]
    check_invariants(f, 2, beams, p.min_points)
    assert len(f.circles) == 0


def test_huge_range_limit_and_huge_ranges():
    r = np.full((2, 361), 1e6, np.float32)
    r[:, 100:200] = 3.0
    f = extract_run(run_of(r, math.radians(0.5), range_max=math.inf))
    check_invariants(f, 2, 361, FeatureParams().min_points)
    assert np.diff(f.seg_offsets).tolist() == [3, 3]  # 1e6 m returns are valid without a range limit


def test_an_empty_run_and_no_beams():
    f = extract_run(run_of(np.zeros((0, 361), np.float32), math.radians(0.5)))
    assert len(f) == 0 and f.seg_offsets.tolist() == [0]
    f = extract_run(run_of(np.zeros((2, 0), np.float32), math.radians(0.5)))
    assert f.seg_offsets.tolist() == [0, 0, 0] and len(f.lines) == 0


@pytest.mark.parametrize("inc", [0.0, math.nan, math.inf])
def test_an_unusable_angle_step_is_an_input_error(inc):
    run = run_of(np.full((1, 10), 2.0, np.float32), 1.0)
    run = ScanRun(run.stamps, run.ranges, ScanGeometry(0.0, inc, 10, 0.0, 8.0))
    with pytest.raises(InputError):
        extract_run(run)
    with pytest.raises(InputError):
        segment_run(run)


def test_a_negative_step_sees_the_same_scene():
    """A negative angle step (clockwise beams) is allowed: the same points in reverse beam order give the same
    segments (mirrored), the same circles and the same walls."""
    inc = math.radians(0.5)
    angles = -math.pi / 2 + np.arange(361) * inc
    clean = np.minimum(ref.ray_wall(angles, 5.0, 0.3), ref.ray_circle(angles, 2.0, 0.5, 0.25))
    clean = np.minimum(clean, ref.ray_circle(angles, 2.5, -1.0, 0.1))
    r = (clean + np.random.default_rng(3).normal(0, 0.005, 361)).astype(np.float32)[None]
    g_pos = ScanGeometry(-math.pi / 2, inc, 361, 0.0, 8.0)
    g_neg = ScanGeometry(angles[-1], -inc, 361, 0.0, 8.0)
    f = extract_run(ScanRun(np.zeros(1, np.int64), r, g_pos), landmarks=False)
    h = extract_run(ScanRun(np.zeros(1, np.int64), r[:, ::-1], g_neg), landmarks=False)
    check_invariants(h, 1, 361, FeatureParams().min_points)
    assert sorted(zip(f.seg_start.tolist(), f.seg_end.tolist(), strict=True)) == sorted(
        zip((361 - h.seg_end).tolist(), (361 - h.seg_start).tolist(), strict=True)
    )
    assert len(h.circles) == len(f.circles) == 2
    for c in f.circles:
        assert np.min(np.hypot(h.circles["x"] - c["x"], h.circles["y"] - c["y"])) < 0.01
    wall_f = f.lines[np.argmax(f.lines["length"])]
    wall_h = h.lines[np.argmax(h.lines["length"])]
    dth, drho = ref.same_line(
        float(wall_f["theta"]), float(wall_f["rho"]), float(wall_h["theta"]), float(wall_h["rho"])
    )
    assert dth < math.radians(0.5) and drho < 0.01


# ----------------------------------------------------------------------------------------------- overflows


def run_isolated(code: str) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter (it may corrupt memory); it prints OK when its checks pass."""
    prelude = textwrap.dedent("""
        import math
        import numpy as np
        from datmo_cli.logs.scan import ScanGeometry, ScanRun
        from datmo_cli.perception.features import extract_run, segment_run
        from datmo_cli.perception.params import FeatureParams
    """)
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )


def test_min_points_two_fills_the_segment_buffer_safely():
    """Alternating ranges make one segment per two beams, the most segment_run's buffer is sized for."""
    res = run_isolated("""
        r = np.tile(np.array([1.0, 1.0, 5.0, 5.0], np.float32), 50)[None]
        run = ScanRun(np.zeros(1, np.int64), r, ScanGeometry(0.0, math.radians(0.5), 200, 0.0, 8.0))
        s, e, o = segment_run(run, FeatureParams(min_points=2))
        assert o.tolist() == [0, 100] and len(s) == 100, (o, len(s))
        f = extract_run(run, FeatureParams(min_points=2))
        assert f.seg_offsets.tolist() == [0, 100] and len(f.blobs) == 100
        print("OK")
    """)
    assert res.returncode == 0 and res.stdout.strip() == "OK", res.stderr[-2000:]


def test_min_points_one_segment_run_one_segment_per_beam():
    res = run_isolated("""
        r = np.tile(np.array([1.0, 5.0], np.float32), 5)[None]     # every beam its own segment
        run = ScanRun(np.zeros(1, np.int64), r, ScanGeometry(0.0, math.radians(0.5), 10, 0.0, 8.0))
        s, e, o = segment_run(run, FeatureParams(min_points=1))
        assert o.tolist() == [0, 10] and len(s) == 10, (o.tolist(), len(s))   # got offsets [0, 10], 6 starts
        assert s.tolist() == list(range(10)) and e.tolist() == list(range(1, 11))
        print("OK")
    """)
    assert res.returncode == 0 and res.stdout.strip() == "OK", res.stderr[-2000:]


def test_min_points_one_extract_run_one_blob_per_beam():
    res = run_isolated("""
        r = np.tile(np.array([1.0, 5.0], np.float32), 5)[None]
        run = ScanRun(np.zeros(1, np.int64), r, ScanGeometry(0.0, math.radians(0.5), 10, 0.0, 8.0))
        f = extract_run(run, FeatureParams(min_points=1))
        assert f.seg_offsets.tolist() == [0, 10] and f.blob_offsets.tolist() == [0, 10], f.blob_offsets
        assert f.blobs["first"].tolist() == list(range(10)) and np.all(f.blobs["kind"] == 1)
        print("OK")
    """)
    assert res.returncode == 0 and res.stdout.strip() == "OK", res.stderr[-2000:]


def test_given_segments_out_of_range_are_clipped_not_trusted():
    run = run_of(np.full((1, 50), 2.0, np.float32), math.radians(0.5))
    f = extract_run(run, segments=(np.array([-5, 40]), np.array([30, 500]), np.array([0, 2])))
    check_invariants(f, 1, 50, 1)
    assert f.seg_start.tolist() == [0, 40] and f.seg_end.tolist() == [30, 50]


def test_overlapping_given_segments_are_a_clean_error_not_an_overflow():
    """More segments than beams (here the whole scan B + 1 times) would overflow the kernel's buffers:
    given segments must be disjoint and in scan order, else an InputError names the scan."""
    res = run_isolated("""
        from datmo_cli.base.errors import InputError
        B = 6
        r = np.full((2, B), 2.0, np.float32)
        run = ScanRun(np.arange(2, dtype=np.int64), r, ScanGeometry(0.0, math.radians(0.5), B, 0.0, 8.0))
        start = np.zeros(2 * (B + 1), np.int64)
        end = np.full(2 * (B + 1), B, np.int64)
        off = np.array([0, B + 1, 2 * (B + 1)])
        try:
            extract_run(run, segments=(start, end, off))
        except InputError as exc:
            assert "scan 0" in str(exc) and "overlaps" in str(exc), exc
        else:
            raise AssertionError("no error")
        f = extract_run(run, segments=(np.array([0, 3, 0]), np.array([3, 6, 6]), np.array([0, 2, 3])))
        assert f.seg_offsets.tolist() == [0, 2, 3] and f.seg_start.tolist() == [0, 3, 0]
        print("OK")
    """)
    assert res.returncode == 0 and res.stdout.strip() == "OK", res.stderr[-2000:]
