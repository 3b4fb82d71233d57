"""Every numba kernel of the package against its plain reference in tests/reference_*.py, on small random or
hand-made inputs; and the table that says, for each kernel, which test checks it directly.

tests/kernel_checks.py maps every compiled function (a numba dispatcher defined in a datmo_cli module) to the
test that calls it and compares it with a reference; `test_every_kernel_has_a_reference_check` fails on a
kernel missing from the table, on a stale entry, and on an entry whose test does not call its kernel.
"""

from __future__ import annotations

import ast
import importlib
import math
import pkgutil
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import datmo_cli
from datmo_cli.perception import hough_lines as HL
from datmo_cli.perception import icp as KI
from datmo_cli.perception import leg_features as LF
from datmo_cli.perception import leg_forest as LFO
from datmo_cli.perception import scan_extractor as SX
from datmo_cli.perception import segmentation as SEG
from datmo_cli.sim import _kernels as KS
from datmo_cli.tracking import _assign, _association, _background, _life_cycle, _people, _scan_measurements
from datmo_cli.tracking import _kernels as KT
from tests import reference_perception as rp
from tests import reference_sim as rs
from tests import reference_tracking as rt
from tests.kernel_checks import CHECKS

pytestmark = [pytest.mark.unit, pytest.mark.kernels]
TESTS = Path(__file__).parent


@cache
def dispatchers() -> frozenset[str]:
    """Every numba-compiled function defined in a datmo_cli module, as 'package.module.name' (no datmo_cli.).
    With NUMBA_DISABLE_JIT=1 there are no dispatchers: the kernels are found by their @njit decorators."""
    from numba.core.dispatcher import Dispatcher

    found = set()
    for info in pkgutil.walk_packages(datmo_cli.__path__, "datmo_cli."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        source = Path(module.__file__).read_text()
        decorated = set(re.findall(r"^@(?:numba\.)?njit[^\n]*\ndef (\w+)\(", source, re.M))
        for name, value in vars(module).items():
            own = getattr(getattr(value, "py_func", value), "__module__", None) == info.name
            if own and (isinstance(value, Dispatcher) or name in decorated):
                found.add(f"{info.name.removeprefix('datmo_cli.')}.{name}")
    return frozenset(found)


@cache
def _functions(file: str) -> dict[str, str]:
    """{name: source} of the top-level functions of test file `file` (parsed once per file)."""
    text = (TESTS / file).read_text()
    lines = text.splitlines()
    body = ast.parse(text).body
    return {f.name: "\n".join(lines[f.lineno - 1 : f.end_lineno]) for f in body if isinstance(f, ast.FunctionDef)}


def _test_source(node: str) -> str:
    """The source of test `node` and of the helpers of its module it calls."""
    file, name = node.split("::")
    funcs = _functions(file)
    assert name in funcs, f"{node}: no such test"
    return "\n".join([funcs[name]] + [s for n, s in funcs.items() if n != name and re.search(rf"\b{n}\(", funcs[name])])


def test_every_kernel_has_a_reference_check():
    found = dispatchers()
    assert len(found) > 100
    assert sorted(found - CHECKS.keys()) == [], "kernels with no reference check: add one to CHECKS"
    assert sorted(CHECKS.keys() - found) == [], "entries for kernels that no longer exist"
    for kernel, node in CHECKS.items():
        name = kernel.rsplit(".", 1)[1]
        assert re.search(rf"\b{name}\(", _test_source(node)), f"{node} does not call {kernel}"


# ------------------------------------------------------------------------------------------ tracking
def _legs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return rng.uniform(0, 3, n), rng.uniform(0, 3, n), rng.uniform(0.05, 0.3, n)


def _equal(got: tuple, want: tuple) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 9))
def test_legs_to_measurements(seed: int, n: int):
    lx, ly, ls = _legs(np.random.default_rng(seed), n)
    got = KT.legs_to_measurements(lx, ly, ls, rt.param_vector(stride_max=0.8))
    _equal(got, rt.legs_to_measurements(lx, ly, ls, 0.8))


def test_people_first():
    lx, ly, ls = _legs(np.random.default_rng(1), 7)
    x, y, size, kind, legs, m = KT._people_first(lx, ly, ls, rt.param_vector(stride_max=0.8), 3)
    want = rt.legs_to_measurements(lx, ly, ls, 0.8)
    assert m == len(want[0]) and len(x) == m + 3
    _equal((x[:m], y[:m], size[:m], kind[:m], legs[:m]), want)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), nc=st.integers(0, 5), nb=st.integers(0, 5), nl=st.integers(0, 6))
def test_paper_measurements(seed: int, nc: int, nb: int, nl: int):
    rng = np.random.default_rng(seed)
    cx, cy, cr = rng.uniform(0, 4, nc), rng.uniform(0, 4, nc), rng.uniform(0.02, 0.4, nc)
    bx, by, bsize, bkind = (
        rng.uniform(0, 4, nb),
        rng.uniform(0, 4, nb),
        rng.uniform(0.02, 0.6, nb),
        rng.integers(0, 2, nb),
    )
    lseg = rng.integers(0, 3, nl)
    lx0, ly0 = rng.uniform(0, 4, nl), rng.uniform(0, 4, nl)
    lx1, ly1 = lx0 + rng.uniform(-0.3, 0.3, nl), ly0 + rng.uniform(-0.3, 0.3, nl)
    args = (cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1)
    prm = rt.param_vector(leg_radius_max=0.13, leg_blob_max=0.3, stride_max=0.8, d_max=0.5)
    got = KT.measurements((cx, cy, cr), (bx, by, bsize, bkind), (lseg, lx0, ly0, lx1, ly1), prm)
    _equal(got, rt.paper_measurements(*args, 0.13, 0.3, 0.8, 0.5))


def test_beam_marks_and_span_max():
    rng = np.random.default_rng(2)
    first = rng.integers(0, 20, 6)
    last = first + rng.integers(0, 5, 6)
    value = rng.uniform(0, 1, 6)
    marks = KT._beam_marks(first, last, value, 30)
    np.testing.assert_array_equal(marks, rt.beam_marks(first, last, value, 30))
    for a, b in [(0, 0), (3, 9), (10, 29), (25, 29)]:
        assert KT._span_max(marks, a, b) == rt.beam_marks(first, last, value, 30)[a : b + 1].max()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), T=st.integers(0, 4), L=st.integers(0, 8))
def test_leg_stage(seed: int, T: int, L: int):
    rng = np.random.default_rng(seed)
    tx, ty = rng.uniform(0, 3, T), rng.uniform(0, 3, T)
    lx, ly, ls = _legs(rng, L)
    prm = rt.param_vector(leg_reach=0.6, stride_max=0.8)
    _equal(KT.leg_stage(tx, ty, lx, ly, ls, prm), rt.leg_stage(tx, ty, lx, ly, ls, 0.6, 0.8))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), T=st.integers(0, 4), L=st.integers(0, 8))
def test_leg_stage_measurements(seed: int, T: int, L: int):
    """Strong and weak candidates (each weak one the measurement of other kind it was measured as) taken by
    tracks; the measurements a taken weak candidate was are dropped, the free strong ones paired again."""
    rng = np.random.default_rng(seed)
    tx, ty = rng.uniform(0, 3, T), rng.uniform(0, 3, T)
    lx, ly, ls = _legs(rng, L)
    M = 6
    mx, my, msize = rng.uniform(0, 3, M), rng.uniform(0, 3, M), rng.uniform(0, 1, M)
    mkind = np.array([0, 1, 2, 3, 4, 4])
    mlegs = np.full((M, 4), np.nan)
    strong = rng.random(L) < 0.5
    cover = np.where(strong, -1, rng.integers(1, M, L))  # a weak candidate on a measurement of other kind, or none
    cover = np.where(cover == 1, -1, cover)
    prm = rt.param_vector(leg_reach=0.6, stride_max=0.8)
    got = KT.leg_stage_measurements(tx, ty, (lx, ly, ls, strong, cover), (mx, my, msize, mkind, mlegs), prm)
    _equal(got, rt.leg_stage_measurements(tx, ty, lx, ly, ls, strong, cover, mx, my, msize, mkind, mlegs, 0.6, 0.8))


def test_a_taken_weak_candidate_is_no_longer_its_measurement():
    """A track takes the weak candidate at its prediction: the blob that candidate was measured as goes; the
    weak candidate no track reaches stays its circle; strong candidates no track took are paired."""
    lx, ly, ls = np.array([1.0, 3.0, 5.0, 5.3]), np.array([0.0, 0.0, 0.0, 0.0]), np.full(4, 0.1)
    strong, cover = np.array([False, False, True, True]), np.array([1, 0, -1, -1])
    mx, my, msize = np.array([3.0, 1.0, 9.0]), np.zeros(3), np.full(3, 0.1)
    mkind, mlegs = np.array([2, 4, 3]), np.full((3, 4), np.nan)
    owner, x, y, size, kind, legs, other = KT.leg_stage_measurements(
        np.array([1.05]),
        np.array([0.0]),
        (lx, ly, ls, strong, cover),
        (mx, my, msize, mkind, mlegs),
        rt.param_vector(leg_reach=0.6, stride_max=0.8),
    )
    np.testing.assert_array_equal(owner, [0])
    np.testing.assert_array_equal(kind, [1, 0, 2, 3])  # the track's leg, the free pair, the circle, the box
    np.testing.assert_array_equal(x, [1.0, 5.15, 3.0, 9.0])
    np.testing.assert_array_equal(other, [0, 2])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(0, 8))
def test_duplicates(seed: int, K: int):
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, 1.5, K), rng.uniform(0, 1.5, K)
    vx, vy = rng.uniform(-1, 1, K), rng.uniform(-1, 1, K)
    vvar = rng.uniform(0, 0.5, K) * (rng.random(K) < 0.5)
    candidate, confirmed = rng.random(K) < 0.7, rng.random(K) < 0.5
    victim = candidate | (rng.random(K) < 0.3)
    rank = rng.integers(0, 3, K)
    args = (x, y, vx, vy, vvar, victim, candidate, confirmed, rank)
    got = KT.duplicates(*args, rt.param_vector(merge_distance=0.5, merge_speed=0.6))
    np.testing.assert_array_equal(got, rt.duplicates(*args, 0.5, 0.6))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(0, 8), inc_sign=st.sampled_from([1.0, -1.0]))
def test_occlusion(seed: int, K: int, inc_sign: float):
    rng = np.random.default_rng(seed)
    B = 181
    inc = inc_sign * math.radians(1.0)
    angle_min = -inc * (B - 1) / 2
    ranges = rng.uniform(0.5, 8.5, B).astype(np.float32)
    ranges[rng.random(B) < 0.1] = np.nan
    r, a = rng.uniform(0, 9, K), rng.uniform(-2.5, 2.5, K)
    sx, sy = r * np.cos(a), r * np.sin(a)
    size, missed = rng.uniform(0, 1, K), rng.random(K) < 0.8
    args = (sx, sy, size, missed, ranges, angle_min, inc, 8.0)
    np.testing.assert_array_equal(KT.occlusion(*args, rt.param_vector(occlusion_margin=0.3)), rt.occlusion(*args, 0.3))


def _grid(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.where(rng.random(n * n) < 0.1, rng.uniform(0, 10, n * n), 0.0)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), L=st.integers(0, 10))
def test_on_background(seed: int, L: int):
    rng = np.random.default_rng(seed)
    n, cell = 20, 0.25
    score = _grid(rng, n)
    lx, ly = rng.uniform(-3, 3, L), rng.uniform(-3, 3, L)  # some off the grid
    ls = rng.uniform(0, 0.4, L)
    prm = rt.param_vector(background_cell=cell, background_time=3.0)
    got = KT.on_background(score, lx, ly, ls, 0.2, -0.1, -2.5, -2.5, n, prm)
    np.testing.assert_array_equal(got, rt.on_background(score, lx, ly, ls, 0.2, -0.1, -2.5, -2.5, cell, n, 3.0))


def test_tracks_on_background():
    rng = np.random.default_rng(4)
    n, cell = 20, 0.25
    score = _grid(rng, n)
    M = 12
    mx, my, msize = rng.uniform(-2.4, 2.4, M), rng.uniform(-2.4, 2.4, M), rng.uniform(0, 0.5, M)
    mkind = rng.integers(0, 5, M)
    rows, cols = np.array([0, 2, 3, 5, 6]), np.array([4, 0, 11, 7, 2])
    args = (score, mx, my, msize, mkind, rows, cols, 8, 0.1, 0.3, -2.5, -2.5)
    want = rt.tracks_on_background(*args, cell, n, 3.0)
    grid = (score, -2.5, -2.5, n)
    prm = rt.param_vector(background_cell=cell, background_time=3.0)
    got = KT.tracks_on_background(grid, mx, my, msize, mkind, rows, cols, 8, 0.1, 0.3, prm)
    np.testing.assert_array_equal(got, want)
    assert want.any() and not want.all()


def _table(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A track table of n tracks with random states and covariances: (table, x (n, 4), P (n, 4, 4))."""
    from datmo_cli.tracking import state

    tab = np.zeros((n, state.n_columns(1)))
    x = rng.normal(0, 2, (n, 4))
    A = rng.normal(size=(n, 4, 4))
    P = 0.1 * A @ A.transpose(0, 2, 1) + 0.01 * np.eye(4)
    tab[:, state.X : state.X + 4] = x
    tab[:, state.P0 : state.P0 + 16] = P.reshape(n, 16)
    return tab, x, P


def test_step_kalman_update_and_restart():
    from datmo_cli.tracking import state

    rng = np.random.default_rng(21)
    tab, x, P = _table(rng, 5)
    rows = np.array([0, 2, 3])
    zx, zy, sigma = rng.normal(0, 2, 3), rng.normal(0, 2, 3), rng.uniform(0.02, 0.3, 3)
    scratch = np.empty((3, 4, 4))
    for q, k in enumerate(rows.tolist()):
        _association.kalman_update(tab, k, zx[q], zy[q], sigma[q], scratch)
    rt.joseph_update(x, P, rows, zx, zy, sigma)
    np.testing.assert_array_equal(tab[:, state.X : state.X + 4], x)
    np.testing.assert_array_equal(tab[:, state.P0 : state.P0 + 16], P.reshape(5, 16))
    prm = rt.param_vector(initial_speed_sigma=0.7)
    _association.restart(tab, 4, 1.5, -0.5, 0.1, prm)
    want = np.diag([0.1**2, 0.1**2, 0.7**2, 0.7**2])
    np.testing.assert_array_equal(tab[4, state.X : state.X + 4], [1.5, -0.5, 0.0, 0.0])
    np.testing.assert_array_equal(tab[4, state.P0 : state.P0 + 16], want.reshape(16))


def test_step_to_sensor():

    rng = np.random.default_rng(22)
    for _ in range(20):
        pose, p = rng.uniform(-3, 3, 3), rng.uniform(-5, 5, 2)
        got = _scan_measurements.to_sensor(p[0], p[1], True, pose)
        want = np.linalg.inv(rp.se2(*pose)) @ [p[0], p[1], 1.0]
        np.testing.assert_allclose(got, want[:2], atol=1e-12)
        assert _scan_measurements.to_sensor(p[0], p[1], False, pose) == (p[0], p[1])


def test_step_gated_costs():
    from datmo_cli.tracking.params import TrackingParams

    rng = np.random.default_rng(23)
    tab, x, P = _table(rng, 6)
    mx, my, kind = rng.normal(0, 2, 9), rng.normal(0, 2, 9), rng.integers(0, 5, 9)
    compat = rng.random((6, 5)) < 0.7
    row = rng.integers(0, 6, 6)
    p = TrackingParams()
    cost, ok = _association.gated_costs(tab, 6, mx, my, kind, compat, row, rt.param_vector())
    want_cost, want_ok = rt.gated_costs(
        x, P, mx, my, kind, p.measurement_noise, p.leg_measurement_noise, p.gate, p.max_gate_distance, compat, row
    )
    np.testing.assert_array_equal(ok, want_ok)
    np.testing.assert_array_equal(cost[ok], want_cost[ok])
    assert np.isinf(cost[~ok]).all() and ok.any() and not ok.all()


def test_step_leggy_tracks_and_duplicates():
    from datmo_cli.tracking import state

    rng = np.random.default_rng(24)
    found = victims = 0
    for _ in range(20):
        n = 8
        tab, x, P = _table(rng, n)
        tab[:, state.X : state.X + 2] = rng.uniform(0, 1.0, (n, 2))  # close together: some within merge_distance
        x[:, :2] = tab[:, state.X : state.X + 2]
        votes = rng.integers(0, 4, (n, 5)) * (rng.random((n, 5)) < 0.6)
        cls, mob = rng.integers(0, 4, n), rng.integers(0, 3, n)
        confirmed, hits = rng.random(n) < 0.6, rng.integers(1, 20, n)
        person, leg_hits = rng.random(n) < 0.3, rng.integers(0, 3, n) * (rng.random(n) < 0.4)
        tab[:, state.VOTES : state.VOTES + 5] = votes
        tab[:, state.CLS], tab[:, state.MOBILITY], tab[:, state.CONFIRMED], tab[:, state.HITS] = (
            cls,
            mob,
            confirmed,
            hits,
        )
        score = rng.random(n)
        tab[:, state.IS_PERSON], tab[:, state.LEG_HITS], tab[:, state.LEG_SCORE] = person, leg_hits, score
        prm = rt.param_vector()
        np.testing.assert_array_equal(
            _people.leggy_tracks(tab, n, prm),
            rt.leggy_tracks(
                votes, cls, confirmed, person, leg_hits, score, prm[state.P_PERSON_VOTES], prm[state.P_PERSON_MAINTAIN]
            ),
        )
        np.testing.assert_array_equal([_people.sure_person(tab, k, prm) for k in range(n)], rt.sure_people(person))
        victim, candidate, rank = rt.duplicate_ranks(
            votes, hits, confirmed, mob, cls, leg_hits, score, prm[state.P_PERSON_MAINTAIN]
        )
        want = rt.duplicates(
            x[:, 0],
            x[:, 1],
            x[:, 2],
            x[:, 3],
            P[:, 2, 2] + P[:, 3, 3],
            victim,
            candidate,
            confirmed,
            rank,
            prm[state.P_MERGE_DISTANCE],
            prm[state.P_MERGE_SPEED],
        )
        np.testing.assert_array_equal(_life_cycle.duplicates(tab, n, True, prm), want)
        found += int(want.sum())
        victims += int((want & ~candidate).sum())
    assert found > 0 and victims > 0


def test_step_kind_group():
    """The kind group of random tracks (votes, mobility, person) is the reference's: a person's is 0 whatever fed
    it."""
    from datmo_cli.tracking import state

    rng = np.random.default_rng(30)
    n = 40
    tab = np.zeros((n, state.n_columns(1)))
    votes = rng.integers(0, 4, (n, 5)) * (rng.random((n, 5)) < 0.6)
    mob, person = rng.integers(0, 3, n), rng.random(n) < 0.3
    tab[:, state.VOTES : state.VOTES + 5], tab[:, state.MOBILITY], tab[:, state.IS_PERSON] = votes, mob, person
    want = rt.kind_groups(votes, mob, person)
    np.testing.assert_array_equal([_association.kind_group(tab, k) for k in range(n)], want)
    assert (want[person] == 0).all() and (rt.kind_groups(votes, mob, np.zeros(n, bool))[person] != 0).any()


def test_step_leg_probability():
    from datmo_cli.tracking.measurements import Measurements

    rng = np.random.default_rng(25)
    for with_prob in (True, False):
        M, L = 7, 5
        raw = np.column_stack([rng.uniform(0, 3, (L, 2)), rng.uniform(0.05, 0.2, L), rng.uniform(0, 1, L)])
        kind = np.array([0, 0, 1, 1, 2, 3, 4])
        legs = np.full((M, 4), np.nan)
        legs[:2] = raw[[0, 2]][:, :2].reshape(1, 4) + rng.normal(0, 0.02, (2, 4))
        m = Measurements(
            rng.uniform(0, 3, M),
            rng.uniform(0, 3, M),
            rng.uniform(0.1, 1, M),
            kind,
            legs,
            raw if with_prob else raw[:, :3],
            rng.uniform(0, 1, M),
        )
        want = rt._leg_probability(m, np.arange(M))
        got = [_people.leg_probability(m.x, m.y, m.kind, m.legs, m.prob, raw, with_prob, j) for j in range(M)]
        np.testing.assert_array_equal(got, want)


def test_step_background_update():
    """Scan after scan (a still sensor, then a moved one), the grid with its range/beam cache equals the
    reference's: scores, active cells in order, and the scans that hit them."""

    rng = np.random.default_rng(26)
    B, n, cell = 91, 40, 0.25
    angles = np.radians(np.linspace(-45.0, 45.0, B))
    inc = angles[1] - angles[0]
    score, mark, active = np.zeros(n * n), np.zeros(n * n, np.int64), np.zeros(400, np.int64)
    cache = np.zeros((400, 2))
    want_score, want_mark, want_active = np.zeros(n * n), np.full(n * n, -1, np.int64), np.zeros(400, np.int64)
    count = want_count = 0
    pose = (0.0, 0.0, 1.0, 0.0)
    for scan in range(1, 25):
        fresh = scan in (1, 13)
        if scan == 13:
            pose = (0.3, -0.2, math.cos(0.2), math.sin(0.2))
        ranges = np.full(B, 3.0, np.float32)
        ranges[rng.random(B) < 0.3] = rng.uniform(0.5, 4.5)
        ranges[rng.random(B) < 0.05] = np.inf
        args = (
            ranges,
            np.cos(angles),
            np.sin(angles),
            angles[0],
            inc,
            0.1,
            8.0,
            *pose,
            0.2,
            -5.0,
            -5.0,
            cell,
            n,
            0.3,
            0.8,
        )
        # a person at 2.5 m then 3 m ahead: their returns add nothing
        people = (np.array([2.5 + 0.5 * (scan > 12)]), np.array([0.1]), 0.4)
        bg, beams, frame, grid = (score, mark, active, cache), args[1:7], args[7:11], args[12:18]
        count = _background.background_update(bg, count, scan, args[0], beams, frame, args[11], grid, fresh, people)
        want_count = rt.background_update(want_score, want_mark, want_active, want_count, scan, *args, *people)
        assert count == want_count
        np.testing.assert_array_equal(active[:count], want_active[:count])
        np.testing.assert_array_equal(score, want_score)
        np.testing.assert_array_equal(np.where(mark == 0, -1, mark), want_mark)
    assert (score >= 0.8).any()


def test_step_carried_update_and_beams():
    """Scan after scan, a sensor driving with some beams' returns fixed to it (a part of the robot, now and then
    hidden), others on a wall it nears, invalid ones, and beams that return one range for a while and another
    after: the carried beams (range kept, travel seen and away) equal the reference's, then which leg candidates
    lie on carried beams; nothing changes without a pose."""
    from datmo_cli.tracking import state

    rng = np.random.default_rng(27)
    B = 91
    angles = np.radians(np.linspace(-45.0, 45.0, B))
    geo = np.array([angles[0], angles[1] - angles[0], 8.0, 1.0, 0.05])
    prm = rt.param_vector(carried_travel=1.0, carried_radius=0.05)
    ctx = state.new_context()
    carry = (np.full(B, np.nan), np.zeros(B), np.zeros(B))
    want = tuple(a.copy() for a in carry)
    carried_seen, last = 0, None
    for k in range(40):
        pose = np.array([0.2 * k, 0.05 * k, 0.02 * k])
        ranges = (6.0 - 0.15 * k + rng.normal(0, 0.01, B)).astype(np.float32)
        ranges[10:25] = 0.7 + rng.normal(0, 0.01, 15)  # carried: within carried_radius of where they settled
        ranges[10:25][rng.random(15) < 0.2] = rng.uniform(0.2, 0.6)  # hidden by something passing, now and then
        ranges[30:33] = rng.choice([np.inf, np.nan, 0.01, 9.0], 3)
        ranges[40:50] = 2.0 if k < 15 else 1.2  # one range for 3 m, then another
        ranges[rng.random(B) < 0.05] = rng.uniform(0.5, 3.0)
        step = 0.0 if last is None else float(np.hypot(pose[0] - last[0], pose[1] - last[1]))
        last = pose
        _background.carried_update(*carry, ranges, True, True, pose, geo, ctx, prm)
        rt.carried_update(*want, ranges, 0.05, 8.0, 0.05, step)
        for got, ref in zip(carry, want, strict=True):
            np.testing.assert_array_equal(got, ref)
        assert (ctx[state.C_CARRY_POSED], ctx[state.C_CARRY_PX], ctx[state.C_CARRY_PY]) == (1.0, *pose[:2])
        raw = np.column_stack([rng.uniform(-1, 8, (12, 2)), rng.uniform(0.05, 0.4, 12), rng.random(12), -np.ones(12)])
        raw[:4, :2] = np.column_stack(
            _world_frame(0.7 * np.cos(angles[[12, 17, 22, 45]]), 0.7 * np.sin(angles[[12, 17, 22, 45]]), pose)
        )
        out = rng.random(12) < 0.2
        was = out.copy()
        _background.carried_beams(out, raw, ranges, *carry, True, pose, geo, prm)
        sx, sy = _sensor_frame(raw[:, 0], raw[:, 1], pose)
        expect = was | rt.carried_beams(sx, sy, raw[:, 2], ranges, *want, geo[0], geo[1], 1.0, 0.05)
        np.testing.assert_array_equal(out, expect)
        carried_seen += int((expect & ~was).sum())
        still = was.copy()
        _background.carried_beams(still, raw, ranges, *carry, False, pose, geo, prm)  # no pose: nothing is carried
        np.testing.assert_array_equal(still, was)
    assert (want[1][10:25] >= 1.0).sum() >= 10 and carried_seen > 0
    # away farther than seen there: the beams took the new range as their reference
    assert (np.abs(want[0][40:50] - 1.2) < 0.01).sum() >= 8
    before = tuple(a.copy() for a in carry)
    _background.carried_update(*carry, ranges, True, False, np.zeros(3), geo, ctx, prm)
    for got, ref in zip(carry, before, strict=True):
        np.testing.assert_array_equal(got, ref)


def _world_frame(x: np.ndarray, y: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sensor-frame points in the tracking frame of a sensor at `pose` (x, y, theta)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return c * x - s * y + pose[0], s * x + c * y + pose[1]


def _sensor_frame(x: np.ndarray, y: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tracking-frame points in the sensor frame of `pose` (x, y, theta)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return c * (x - pose[0]) + s * (y - pose[1]), -s * (x - pose[0]) + c * (y - pose[1])


def test_step_fold_evidence():
    """Leg-candidate hits folded one by one: the plain mean of the first 1/leg_evidence_rate, then a running mean
    of that rate."""
    from datmo_cli.tracking import state

    rng = np.random.default_rng(28)
    prm = rt.param_vector(leg_evidence_rate=0.1)
    tab = np.zeros((4, state.n_columns(1)))
    score, hits = np.zeros(4), np.zeros(4, np.int64)
    p = np.where(
        rng.random(40) < 0.15, _scan_measurements.NOT_A_LEG, rng.random(40)
    )  # some on the background or carried
    assert rt.NOT_A_LEG == _scan_measurements.NOT_A_LEG
    for q in range(40):
        k = int(rng.integers(0, 4))
        _people.fold_evidence(tab, k, p[q], prm)
        rt.fold_evidence(score, hits, k, p[q], 0.1)
    np.testing.assert_array_equal(tab[:, state.LEG_SCORE], score)
    np.testing.assert_array_equal(tab[:, state.LEG_HITS], hits)
    first, ten = (np.zeros(1, np.int64), np.zeros(1)), rng.random(10)
    for q in range(10):
        rt.fold_evidence(first[1], first[0], 0, ten[q], 0.1)
    np.testing.assert_allclose(first[1][0], ten.mean(), rtol=1e-12)  # ten hits: their plain mean
    rt.fold_evidence(first[1], first[0], 0, rt.NOT_A_LEG, 0.1)
    assert first[1][0] == 0.0 and first[0][0] == 11  # a candidate found on the background
    rt.fold_evidence(first[1], first[0], 0, 0.5, 0.1)
    rt.fold_evidence(first[1], first[0], 0, rt.CARRIED_LEG, 0.1)
    assert first[1][0] == 0.0 and first[0][0] == 13  # ... or carried


def test_cover():
    """Measurements (beam ranges) one after the other: each weak candidate is covered by the one sharing most
    beams with it, the first on ties, -1 by none."""
    rng = np.random.default_rng(29)
    for _ in range(30):
        W = int(rng.integers(0, 6))
        wfirst = rng.integers(0, 40, W)
        wlast = wfirst + rng.integers(0, 8, W)
        cover, best = np.full(W, -1, np.int64), np.zeros(W, np.int64)
        want_cover, want_best = cover.copy(), best.copy()
        for m in range(int(rng.integers(0, 6))):
            f = int(rng.integers(0, 45))
            e = f + int(rng.integers(0, 10))
            KT._cover(cover, best, wfirst, wlast, f, e, m)
            rt.cover(want_cover, want_best, wfirst, wlast, f, e, m)
            np.testing.assert_array_equal(cover, want_cover)
            np.testing.assert_array_equal(best, want_best)


def test_components():
    rng = np.random.default_rng(5)
    for _ in range(20):
        nr, nc = int(rng.integers(1, 7)), int(rng.integers(1, 7))
        allowed = rng.random((nr, nc)) < 0.25
        rows, cols = np.arange(nr, dtype=np.int64), np.arange(nc, dtype=np.int64)
        _equal(_assign._components(allowed, rows, cols, nr, nc), rt.components(allowed))


# ----------------------------------------------------------------------------------------------- sim
def test_ray_segment_and_circle():
    rng = np.random.default_rng(6)
    for _ in range(300):
        o, a = rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)
        d = np.array([np.cos(a), np.sin(a)])
        p, q = rng.uniform(-4, 4, 2), rng.uniform(-4, 4, 2)
        c, r = rng.uniform(-4, 4, 2), float(rng.uniform(0.05, 1.0))
        got = KS._ray_segment(o[0], o[1], d[0], d[1], p[0], p[1], q[0], q[1])
        want = rs.ray_segment(o, d, p, q)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-9) or (math.isinf(got) and math.isinf(want))
        got = KS._ray_circle(o[0], o[1], d[0], d[1], c[0], c[1], r)
        want = rs.ray_circle(o, d, c, r)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-9) or (math.isinf(got) and math.isinf(want))


def test_cast_batch():
    """Every beam of two scans against the reference cast: static and moving segments and circles, owners
    included; beams that graze an end or a tangent (a turn of 1e-7 rad changes what they hit) are left out."""
    rng = np.random.default_rng(15)
    angles = np.radians(np.arange(-90.0, 90.5, 2.0))
    poses = np.array([[0.0, 0.0, 0.1], [0.3, -0.2, -0.4]])
    seg_s, circ_s = rng.uniform(-6, 6, (5, 4)), np.column_stack([rng.uniform(-5, 5, (4, 2)), rng.uniform(0.1, 0.6, 4)])
    seg_d = rng.uniform(-6, 6, (2, 2, 4))
    circ_d = np.concatenate([rng.uniform(-5, 5, (2, 3, 2)), rng.uniform(0.1, 0.4, (2, 3, 1))], axis=2)
    own_seg_s, own_circ_s = np.arange(5, dtype=np.int32), np.arange(5, 9, dtype=np.int32)
    own_seg_d, own_circ_d = np.arange(9, 11, dtype=np.int32), np.arange(11, 14, dtype=np.int32)
    out_t, out_owner = np.empty((2, len(angles))), np.empty((2, len(angles)), np.int32)
    KS.cast_batch(
        poses, angles, seg_s, own_seg_s, circ_s, own_circ_s, seg_d, own_seg_d, circ_d, own_circ_d, out_t, out_owner
    )
    owners = np.concatenate([own_seg_s, own_seg_d, own_circ_s, own_circ_d])
    compared = 0
    for k in range(2):
        segs, circs = np.concatenate([seg_s, seg_d[k]]), np.concatenate([circ_s, circ_d[k]])
        best, who, _ = rs.cast(poses[k], angles, segs, circs)
        _, who_lo, _ = rs.cast(poses[k], angles - 1e-7, segs, circs)
        _, who_hi, _ = rs.cast(poses[k], angles + 1e-7, segs, circs)
        steady = (who_lo == who) & (who_hi == who)
        np.testing.assert_allclose(out_t[k][steady], best[steady], rtol=1e-9)
        want = np.where(who[steady] >= 0, owners[np.maximum(who[steady], 0)], -1)
        np.testing.assert_array_equal(out_owner[k][steady], want)
        compared += int(steady.sum())
    assert compared > 150 and (out_owner >= 0).sum() > 40


# ------------------------------------------------------------------------------------------ perception
def test_valid_return():
    for r in [0.0, 0.05, 0.1, 3.0, 8.0, 8.1, np.inf, -np.inf, np.nan]:
        assert SEG.valid_return(r, 0.05, 8.0) == rp.is_valid(r, 0.05, 8.0)


@settings(max_examples=200, deadline=None)
@given(st.floats(-10, 10), st.floats(-10, 10))
def test_atan2(y: float, x: float):
    """The polynomial atan2 is within its stated 0.0015 rad of the exact one (0 at the origin)."""
    want = 0.0 if x == 0 and y == 0 else math.atan2(y, x)
    d = (HL._atan2(y, x) - want + math.pi) % (2 * math.pi) - math.pi
    assert abs(d) <= 0.0015


def test_bounding_box_and_row_offset():
    rng = np.random.default_rng(7)
    x, y = rng.uniform(-3, 3, 30), rng.uniform(-3, 3, 30)
    box = np.empty(4)
    width = HL._bounding_box(x, y, 4, 25, 0.02, 10_000, box)
    lo, want_width = rp.box_rho_offsets(x[4:25].tolist(), y[4:25].tolist(), 8, 0.02)
    assert box.tolist() == [x[4:25].min(), x[4:25].max(), y[4:25].min(), y[4:25].max()]
    assert width == want_width
    assert HL._bounding_box(x, y, 4, 25, 0.02, 50, box) == min(want_width, 50)
    for t, th in enumerate(rp.theta_table(8)):
        assert HL._row_offset(box, math.cos(th), math.sin(th)) == pytest.approx(lo[t], abs=1e-12)


def test_segment_block():
    rng = np.random.default_rng(19)
    inc = math.radians(0.5)
    ranges = np.repeat(rng.uniform(0.5, 6.0, (4, 1)), 120, axis=1) + rng.normal(0, 0.3, (4, 120))
    ranges[rng.random((4, 120)) < 0.08] = np.nan
    seg = np.empty((4 * 120, 2), np.int64)
    count = np.zeros(4, np.int64)
    c1 = math.sqrt(2.0 * (1.0 - math.cos(inc)))
    total = SEG.segment_block(ranges, math.cos(inc), 0.05, c1, 0.1, 8.0, 3, seg, count)
    want = [rp.segment(r, inc, 0.05, 0.1, 8.0, 3) for r in ranges]
    assert count.tolist() == [len(w) for w in want] and total == sum(count)
    assert [tuple(s) for s in seg[:total].tolist()] == [s for w in want for s in w]
    assert total >= 4


def test_scatter():
    rng = np.random.default_rng(17)
    x, y = rng.uniform(-3, 3, 20), rng.uniform(-3, 3, 20)
    idx = rng.permutation(20)
    cx, cy, sxx, syy, sxy = HL.scatter(x, y, idx, 12)
    px, py = x[idx[:12]], y[idx[:12]]
    np.testing.assert_allclose([cx, cy], [px.mean(), py.mean()], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        [sxx, syy, sxy],
        [((px - px.mean()) ** 2).sum(), ((py - py.mean()) ** 2).sum(), ((px - px.mean()) * (py - py.mean())).sum()],
        rtol=1e-12,
    )


def test_one_line():
    rng = np.random.default_rng(18)
    seen = set()
    for _ in range(300):
        n = int(rng.integers(4, 30))
        t = np.sort(rng.uniform(-1, 1, n))
        theta = rng.uniform(0, np.pi)
        x = 2 * np.cos(theta) - t * np.sin(theta) + rng.normal(0, 0.01, n)
        y = 2 * np.sin(theta) + t * np.cos(theta) + rng.normal(0, 0.01, n)
        if rng.random() < 0.5:  # a bend at the end
            x[-3:] += rng.uniform(0, 0.2)
        tol, tail = float(rng.choice([0.01, 0.02, 0.05])), int(rng.integers(1, 4))
        if min(abs(d - tol) for d in rp.line_distances(x, y)) < 1e-9:
            continue  # a point on the tolerance itself: rounding decides
        want = rp.one_line(x, y, tol, tail)
        assert HL._one_line(np.concatenate([[9.0], x]), np.concatenate([[9.0], y]), 1, n + 1, tol, tail) == want
        seen.add(want)
    assert seen == {True, False}


def test_perpendicular_and_convex():
    rng = np.random.default_rng(8)
    for _ in range(200):
        t1, t2, tol = rng.uniform(0, math.pi), rng.uniform(0, math.pi), rng.uniform(0.01, 0.3)
        assert SX._perpendicular(t1, t2, tol) == rp.perpendicular(t1, t2, tol)
        a, j, b = rng.uniform(0.5, 4, 2), rng.uniform(0.5, 4, 2), rng.uniform(0.5, 4, 2)
        assert SX._convex(a[0], a[1], j[0], j[1], b[0], b[1]) == rp.convex(a, j, b)


def test_robust_weight():
    for ares in [0.0, 0.01, 0.05, 0.2, 3.0]:
        for redescend in (False, True):
            assert KI.robust_weight(ares, 0.05, redescend) == pytest.approx(rp.weight(ares, 0.05, redescend), rel=1e-12)


def test_solve3():
    rng = np.random.default_rng(9)
    out = np.empty(3)
    for _ in range(50):
        A = rng.normal(size=(3, 3))
        a, b = A @ A.T + 0.1 * np.eye(3), rng.normal(size=3)
        assert KI.solve3(a, b, out)
        np.testing.assert_allclose(out, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    assert not KI.solve3(np.ones((3, 3)), np.ones(3), out)


def test_compose_and_between():
    rng = np.random.default_rng(10)
    for _ in range(50):
        a, b = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)
        np.testing.assert_allclose(rp.se2(*KI.compose(*a, *b)), rp.se2(*a) @ rp.se2(*b), atol=1e-12)
        np.testing.assert_allclose(KI.between(*a, *b), rp.pose_of(np.linalg.inv(rp.se2(*a)) @ rp.se2(*b)), atol=1e-12)


def test_add_to_map():
    rng = np.random.default_rng(16)
    cap, cell = 60, 0.25
    local_map = KI.new_local_map(cap, cell)
    buckets = len(local_map.head)
    assert buckets >= 2 * cap and buckets & (buckets - 1) == 0 and (local_map.head == KI.EMPTY).all()
    assert local_map.cell == cell and len(local_map.mx) == len(local_map.nxt) == cap
    mx, my, mnx, mny = local_map.mx, local_map.my, local_map.mnx, local_map.mny
    ref_xy, ref_n, count = np.zeros((0, 2)), np.zeros((0, 2)), 0
    for scan in range(4):  # the later scans overlap the earlier ones: their points near the map are skipped
        pts = rng.uniform(-2, 2, (50, 2))
        ang = rng.uniform(-np.pi, np.pi, 50)
        nrm = np.column_stack([np.cos(ang), np.sin(ang)])
        nrm[rng.random(50) < 0.2] = np.nan
        pose = rng.uniform(-0.3, 0.3, 3)
        points = (pts[:, 0].copy(), pts[:, 1].copy(), nrm[:, 0].copy(), nrm[:, 1].copy())
        count = KI.add_to_map(points, 50, tuple(pose), 0.2 if scan else 0.0, local_map, count)
        ref_xy, ref_n = rp.add_to_map(pts, nrm, pose, 0.2 if scan else 0.0, ref_xy, ref_n, cap)
        assert count == len(ref_xy)
        np.testing.assert_allclose(np.column_stack([mx, my])[:count], ref_xy, atol=1e-12)
        np.testing.assert_allclose(np.column_stack([mnx, mny])[:count], ref_n, atol=1e-12)
    assert count == cap  # the map filled up


def test_cell_of_and_hash():
    for x in [-1.01, -0.5, -0.0, 0.0, 0.24, 0.25, 3.7]:
        assert KI.cell_of(x, 0.25) == math.floor(x / 0.25)
    mask = 1023
    for ix, iy in [(0, 0), (1, -1), (-7, 300), (12345, -6789)]:
        assert KI.cell_hash(ix, iy, mask) == rp.cell_hash(ix, iy, mask)


# -------------------------------------------------------------------------------------------- legs
def _scan(seed: int, N: int = 2, B: int = 40) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.5, 4.0, (N, B)).astype(np.float32)
    ranges[rng.random((N, B)) < 0.1] = np.nan
    ranges[rng.random((N, B)) < 0.05] = 0.01  # under range_min
    return ranges, np.radians(np.linspace(-40.0, 40.0, B))


def test_gap_pass_and_block_features():
    from datmo_cli.perception import legs

    for seed in range(6):
        ranges, angles = _scan(seed)
        N, B = ranges.shape
        cos_a, sin_a = np.cos(angles), np.sin(angles)
        counts = np.zeros(N, np.int64)
        none = np.zeros(0, np.int64)
        LF._gap_pass(ranges, cos_a, sin_a, 0.05, 30.0, 0.13, 3, none, none, counts)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        start, end = np.empty(offsets[-1], np.int64), np.empty(offsets[-1], np.int64)
        LF._gap_pass(ranges, cos_a, sin_a, 0.05, 30.0, 0.13, 3, start, end, counts)
        want = rp.gap_clusters(ranges, angles, 0.05, 30.0, 0.13, 3)
        assert [start.tolist(), end.tolist(), offsets.tolist()] == [w.tolist() for w in want]
        assert LF.check_segments(start, end, offsets, B) == rp.check_segments(start, end, offsets, B) == 0
        out = np.zeros((len(start), LF.N_FEATURES))
        beams = (cos_a, sin_a, angles, abs(angles[1] - angles[0]))
        rules = (
            0.05,
            30.0,
            legs.RADIUS_CLIP,
            legs.OCCLUSION_MARGIN,
            legs.CANDIDATE_MAX_WIDTH,
            legs.CANDIDATE_MIN_POINTS,
        )
        LF.block_features(ranges, beams, (start, end, offsets), rules, False, out)
        np.testing.assert_allclose(
            out, rp.cluster_features(ranges, angles, start, end, offsets, 0.05, 30.0), rtol=1e-6, atol=1e-7
        )


def test_check_segments():
    cases = [
        ([0, 5], [4, 9], [0, 1, 2], 10),
        ([0], [11], [0, 1], 10),
        ([3], [2], [0, 1], 10),
        ([0, 5], [4, 9], [0, 2, 1], 10),
        ([0], [4], [1, 1], 10),
        ([], [], [0, 0], 10),
        ([], [], [], 10),
    ]
    for s, e, o, B in cases:
        s, e, o = np.array(s, np.int64), np.array(e, np.int64), np.array(o, np.int64)
        assert LF.check_segments(s, e, o, B) == rp.check_segments(s, e, o, B)


def test_median_and_jump():
    rng = np.random.default_rng(11)
    work = np.empty(200)
    for n in [1, 2, 5, 64, 65, 150]:
        v = rng.normal(size=n)
        assert LF._median(v, n, work) == np.median(v)
    ranges, _ = _scan(12, 1, 30)
    r = ranges[0]
    for i in np.flatnonzero([rp.is_valid(float(v), 0.05, 30.0) for v in r]).tolist():  # the ends of segments
        for d in (1, -1):
            assert LF._jump(r, i, d, 30, 0.05, 30.0) == rp.jump(r, i, d, 0.05, 30.0)


def test_ensemble_leaf_and_candidates():
    from datmo_cli.perception.leg_model import load_leg_model
    from datmo_cli.perception.legs import CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS

    model = load_leg_model("default")
    m = model._kernel_args()
    nodes, split, roots = m.nodes, m.split, m.roots
    rng = np.random.default_rng(13)
    ranges, angles = _scan(14, 3, 60)
    start, end, offsets = rp.gap_clusters(ranges, angles, 0.05, 30.0, 0.13, 1)
    X = rp.cluster_features(ranges, angles, start, end, offsets, 0.05, 30.0)
    X = np.concatenate([X, X * rng.uniform(0.5, 1.5, X.shape)])
    out = np.empty(len(X))
    LFO.ensemble(X, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, *model._kernel_args(), out)
    assert m.depth == 5  # the shipped model walks its perfect trees
    by_nodes = np.empty(len(X))
    LFO.ensemble_nodes(
        X, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, nodes, split, roots, m.kind, m.base, m.scale, by_nodes
    )
    np.testing.assert_array_equal(out, by_nodes)
    for x, got in zip(X, out, strict=True):
        candidate = rp.is_candidate(x)
        assert LFO.is_candidate(x, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS) == candidate
        leaves = [rp.tree_leaf(model, root, x) for root in model.roots]
        assert [LFO._leaf(nodes, split, x, root) for root in model.roots] == leaves
        want = rp.ensemble_probability(model, leaves) if candidate else 0.0
        assert got == pytest.approx(want, rel=1e-12, abs=1e-15)
    assert (out > 0).any()
    for q in range(0, len(X) - 3, 4):
        for root in model.roots[:3]:
            got = LFO._leaves4(nodes, split, X[q], X[q + 1], X[q + 2], X[q + 3], root)
            assert list(got) == [rp.tree_leaf(model, root, X[q + i]) for i in range(4)]


def _random_model(rng, n_trees: int, max_depth: int, kind: str):
    """A LegModel of random trees (leaves at any depth up to max_depth, depth-first numbering) whose thresholds
    lie between float32 values, so rounding them to float32 would move rows."""
    from datmo_cli.perception.leg_model import LegModel

    feature, threshold, left, right, value, roots = [], [], [], [], [], []

    def grow(depth: int) -> int:
        i = len(feature)
        for a in (feature, threshold, left, right, value):
            a.append(-1 if a is not threshold and a is not value else 0.0)
        value[i] = float(rng.normal())
        if depth == max_depth or (depth > 0 and rng.random() < 0.3):
            return i
        feature[i] = int(rng.integers(0, 21))
        threshold[i] = float(np.float32(rng.uniform(-1, 1))) + 1e-9 * rng.choice([-1.0, 1.0])
        left[i] = grow(depth + 1)
        right[i] = grow(depth + 1)
        return i

    for _ in range(n_trees):
        roots.append(grow(0))
    return LegModel(feature, threshold, left, right, value, roots, kind=kind, base=0.3, scale=0.7)


@pytest.mark.parametrize("max_depth", [0, 1, 3, 6, 11])
@pytest.mark.parametrize("kind", ["forest", "boosting"])
def test_perfect_trees_equal_the_reference_walk(max_depth, kind):
    """ensemble on the perfect trees (or the node walk, for a model deeper than PERFECT_MAX_DEPTH) gives exactly
    the reference walk's probability (float32 rows against float64 thresholds, NaN to the right), summed tree
    by tree; perfect_sum is that sum."""
    from datmo_cli.perception.leg_model import PERFECT_MAX_DEPTH

    rng = np.random.default_rng(max_depth)
    model = _random_model(rng, 30, max_depth, kind)
    args = model._kernel_args()
    pf, pt, pv, depth = args.perfect_feature, args.perfect_threshold, args.perfect_value, args.depth
    assert depth == (-1 if max_depth > PERFECT_MAX_DEPTH else max_depth)
    X = rng.uniform(-1, 1, (300, 21))
    used = model.feature >= 0
    if used.any():  # values on and about the thresholds, and NaN
        picks = rng.integers(0, used.sum(), X.shape)
        X = np.where(rng.random(X.shape) < 0.5, model.threshold[used][picks], X)
    X[::7, 5] = np.float32(X[::7, 5])
    X[::11, 9] = np.nan
    X[:, 0], X[:, 1] = 3 + rng.integers(0, 9, len(X)), rng.uniform(0, 0.8, len(X))
    X[::13, 1] = 2.0  # not a candidate
    out = np.empty(len(X))
    LFO.ensemble(X, 0.8, 3, *args, out)
    for x, got in zip(X, out, strict=True):
        leaves = [rp.tree_leaf(model, root, x) for root in model.roots]
        assert got == (rp.ensemble_probability(model, leaves) if rp.is_candidate(x) else 0.0)
        if depth >= 0:
            assert LFO.perfect_sum(x.astype(np.float32), pf, pt, pv, depth) == sum(
                (float(model.value[leaf]) for leaf in leaves), 0.0
            )
    if depth >= 0:
        acc = np.empty(16)
        LFO.perfect_sums8(X[:16].astype(np.float32), pf, pt, pv, depth, acc)
        assert acc.tolist() == [LFO.perfect_sum(x.astype(np.float32), pf, pt, pv, depth) for x in X[:16]]


def test_block_probabilities():
    """Features of the candidates (the reference's, to 1e-6) and their probability by the reference tree walk
    over the features the kernel computed; non-candidates 0; the threaded kernel gives the same, split in parts."""
    from datmo_cli.perception import legs
    from datmo_cli.perception.leg_model import load_leg_model

    model = load_leg_model("default")
    rng = np.random.default_rng(20)
    angles = np.radians(np.linspace(-40.0, 40.0, 120))
    ranges = (3.0 + rng.normal(0, 0.005, (4, 120))).astype(np.float32)  # a wall: wide, not a candidate
    for k in range(4):  # two legs in front of it: short arcs 1.2-2 m away
        for i in rng.choice(np.arange(5, 110, 12), 2, replace=False):
            d = rng.uniform(1.2, 2.0)
            ranges[k, i : i + 6] = d + 0.06 * (1 - np.cos(np.linspace(-1.2, 1.2, 6)))
    start, end, offsets = rp.gap_clusters(ranges, angles, 0.05, 30.0, 0.13, 1)
    beams = (np.cos(angles), np.sin(angles), angles, abs(angles[1] - angles[0]))
    rules = (0.05, 30.0, legs.RADIUS_CLIP, legs.OCCLUSION_MARGIN, legs.CANDIDATE_MAX_WIDTH, legs.CANDIDATE_MIN_POINTS)
    args = (beams, (start, end, offsets), rules, model._kernel_args())
    feats, out = np.empty((len(start), LF.N_FEATURES)), np.empty(len(start))
    LFO.block_probabilities(ranges, *args, feats, out)
    want_feats = rp.cluster_features(ranges, angles, start, end, offsets, 0.05, 30.0)
    candidate = np.array([rp.is_candidate(x) for x in want_feats])
    assert candidate.any() and not candidate.all()
    np.testing.assert_allclose(feats[candidate], want_feats[candidate], rtol=1e-6, atol=1e-7)
    want = [
        rp.ensemble_probability(model, [rp.tree_leaf(model, root, x) for root in model.roots]) if c else 0.0
        for x, c in zip(feats, candidate, strict=True)
    ]
    np.testing.assert_allclose(out, want, rtol=1e-12, atol=1e-15)
    feats2, out2 = np.empty_like(feats), np.empty_like(out)
    LFO.block_probabilities_parallel(ranges, 2, *args, feats2, out2)
    np.testing.assert_array_equal(out2, out)


# ------------------------------------------------------------------------------------------------- HTL votes
def test_vote_and_clear():
    """Points voting into the flat accumulator adapted to their bounding box: in every theta cell (a window
    as wide as the table) and in a wrapping window about each point's own cell; the votes and the peak are
    the reference accumulator's; _clear zeroes the rows voted in."""
    rng = np.random.default_rng(37)
    nt, rho_res = 60, 0.02
    cos_t, sin_t = np.cos(np.array(rp.theta_table(nt))), np.sin(np.array(rp.theta_table(nt)))
    for trial in range(6):
        n = int(rng.integers(3, 40))
        t = np.sort(rng.uniform(-0.5, 0.5, n))
        th = rng.uniform(0, np.pi)
        x = 1.5 * np.cos(th) - t * np.sin(th) + rng.normal(0, 0.01, n)
        y = 1.5 * np.sin(th) + t * np.cos(th) + rng.normal(0, 0.01, n)
        box = np.empty(4)
        width = HL._bounding_box(x, y, 0, n, rho_res, 10_000, box)
        acc, lo, touched = np.zeros(nt * width, np.int32), np.empty(nt), np.zeros(nt, np.bool_)
        k = nt if trial % 2 == 0 else int(rng.integers(1, 8))
        cells = rng.integers(0, nt, n)
        peak = (0, 0, 0)
        for i in range(n):
            peak = HL._vote(x[i], y[i], acc, lo, touched, box, cos_t, sin_t, (1.0 / rho_res, width, cells[i], k), peak)
        windows = None if 2 * k + 1 >= nt else [[(c + j) % nt for j in range(-k, k + 1)] for c in cells.tolist()]
        want, want_peak = rp.htl_accumulator(x.tolist(), y.tolist(), nt, rho_res, windows)
        got = {(int(j) // width, int(j) % width): int(acc[j]) for j in np.flatnonzero(acc)}
        assert got == want and peak == want_peak
        assert touched.tolist() == [any(tt == c for tt, _ in want) for c in range(nt)]
        HL._clear(acc, touched, width)
        assert not acc.any() and not touched.any()
