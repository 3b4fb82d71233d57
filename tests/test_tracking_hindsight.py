"""Hindsight (tracking/hindsight.py): the fixed-lag RTS smoother against filterpy's RTS smoother (the oracle),
memory bounded by the lag, person labels back-filled over the lag, and where it applies (datmo run and datmo
track) and where it does not (the live paths)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from datmo_cli.logs.vocabulary import CLASS_PERSON, CLASS_UNKNOWN, STATUS_CONFIRMED, STATUS_TENTATIVE
from datmo_cli.tracking import hindsight as H
from datmo_cli.tracking.bundles import RtsWork
from datmo_cli.tracking.tracker import TRACK_DTYPE, TrackBlock
from tests import reference_tracking as rt

pytestmark = pytest.mark.unit

Q = 2.0  # (m/s²)²/Hz


def filtered_track(n: int, seed: int, q: float = Q, sigma: float = 0.1):
    """A constant-velocity walker measured at uneven steps, filtered by filterpy's KalmanFilter: (stamps ns,
    filtered states (n, 4), covariances (n, 4, 4), F per step, Q per step) as filterpy's rts_smoother takes them."""
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.05, 0.3, n)
    dt[0] = 0.0
    t = np.cumsum(dt)
    truth = np.stack([1.0 + 0.8 * t + 0.2 * np.sin(t), -0.5 + 0.3 * t], axis=1)
    z = truth + rng.normal(0, sigma, truth.shape)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.x = np.array([z[0, 0], z[0, 1], 0.0, 0.0])
    kf.P = np.diag([sigma**2, sigma**2, 1.0, 1.0])
    kf.H = np.eye(2, 4)
    kf.R = sigma**2 * np.eye(2)
    Fs, Qs, xs, Ps = [], [], [], []
    for k in range(n):
        F = rt.rts_transition(np.array([dt[k]]))[0]
        Qk = rt.rts_process_noise(np.array([dt[k]]), np.array([q]))[0]
        if k:
            kf.predict(F=F, Q=Qk)
            kf.update(z[k])
        Fs.append(F)
        Qs.append(Qk)
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
    stamps = (t * 1e9).round().astype(np.int64) + 1_000_000_000
    return stamps, np.array(xs), np.array(Ps), np.array(Fs), np.array(Qs)


def rts(xs, Ps, Fs, Qs):
    from filterpy.kalman import rts_smoother

    # filterpy's module-level smoother steps from k to k + 1 with Fs[k], Qs[k]: ours are stored at k + 1
    x, P, _, _ = rts_smoother(xs, Ps, np.roll(Fs, -1, axis=0), np.roll(Qs, -1, axis=0))
    return x, P


def test_a_lag_longer_than_the_track_is_filterpys_rts_smoother():
    stamps, xs, Ps, Fs, Qs = filtered_track(40, seed=1)
    ids = np.full(len(stamps), 7)
    got, cov = H.smooth(stamps, ids, xs, Ps, np.full(len(stamps), Q), np.arange(len(stamps)), 10**12)
    want, want_cov = rts(xs, Ps, Fs, Qs)
    np.testing.assert_allclose(got, want, atol=1e-9)
    np.testing.assert_allclose(cov, want_cov, atol=1e-9)
    assert np.abs(got - xs).max() > 0.01  # it did smooth


def test_each_row_is_smoothed_over_the_rows_up_to_the_lag_after_it():
    """The slow reference: filterpy's RTS over the track's rows up to lag after each row, that row taken."""
    a = filtered_track(30, seed=2)
    b = filtered_track(25, seed=3)
    lag_ns = 700_000_000
    stamps = np.concatenate([a[0], b[0] + 400_000_000])
    ids = np.concatenate([np.full(30, 1), np.full(25, 2)])
    xs, Ps = np.concatenate([a[1], b[1]]), np.concatenate([a[2], b[2]])
    order = np.argsort(stamps, kind="stable")  # rows in scan order, the two tracks interleaved
    got, cov = H.smooth(stamps[order], ids[order], xs[order], Ps[order], np.full(55, Q), np.arange(55), lag_ns)
    for track, first in ((a, 0), (b, 30)):
        t = track[0] + (0 if first == 0 else 400_000_000)
        for k in range(len(t)):
            j = int(np.searchsorted(t, t[k] + lag_ns, side="right"))
            want, want_cov = rts(track[1][:j], track[2][:j], track[3][:j], track[4][:j])
            row = int(np.flatnonzero(order == first + k)[0])
            np.testing.assert_allclose(got[row], want[k], atol=1e-9)
            np.testing.assert_allclose(cov[row], want_cov[k], atol=1e-9)


def block_of(stamps: np.ndarray, ids: list[list[int]], xs: dict, Ps: dict, classes=None, statuses=None) -> TrackBlock:
    """A TrackBlock of scans whose tracks are ids[k] (states from xs[id][k], sensor frame, no poses)."""
    rows = []
    for k, live in enumerate(ids):
        for i in live:
            r = np.zeros(1, TRACK_DTYPE)
            r["id"] = i
            r["x"], r["y"], r["vx"], r["vy"] = xs[i][k]
            r["covariance"] = Ps[i][k].ravel()
            r["classification"] = CLASS_UNKNOWN if classes is None else classes[i][k]
            r["status"] = STATUS_CONFIRMED if statuses is None else statuses[i][k]
            rows.append(r)
    offsets = np.concatenate([[0], np.cumsum([len(x) for x in ids])]).astype(np.int64)
    items = np.concatenate(rows) if rows else np.zeros(0, TRACK_DTYPE)
    return TrackBlock(offsets, items, np.zeros((0, 1, 2)), np.zeros(0, np.int64))


def sub(block: TrackBlock, a: int, b: int) -> TrackBlock:
    o = block.offsets
    return TrackBlock(o[a : b + 1] - o[a], block.items[o[a] : o[b]], block.tail, block.tail_count)


def run_buffer(stamps, block, lag: float, chunk: int, most: list | None = None):
    """Push `block` through a Hindsight `chunk` scans at a time: (released stamps, released items)."""
    h = H.Hindsight(lag, Q, Q)
    got_stamps, got = [], []
    for a in range(0, len(stamps), chunk):
        b = min(a + chunk, len(stamps))
        h.push(stamps[a:b], sub(block, a, b), None)
        if most is not None:
            most.append(len(h))
        s, out, _ = h.release()
        got_stamps.append(s)
        got.append(out.items)
    s, out, _ = h.release(final=True)
    assert len(h) == 0
    return np.concatenate(got_stamps + [s]), np.concatenate(got + [out.items])


def test_released_tracks_are_the_same_whatever_the_chunks_and_memory_is_bounded_by_the_lag():
    stamps, xs, Ps, _, _ = filtered_track(120, seed=4)
    block = block_of(stamps, [[5]] * len(stamps), {5: xs}, {5: Ps})
    lag = 0.8
    smoothed, _ = H.smooth(stamps, np.full(len(stamps), 5), xs, Ps, np.full(len(stamps), Q), np.arange(120), 8 * 10**8)
    period = np.diff(stamps).min() * 1e-9
    for chunk in (1, 7, 120):
        most: list[int] = []
        s, items = run_buffer(stamps, block, lag, chunk, most)
        assert np.array_equal(s, stamps)
        got = np.stack([items[k] for k in ("x", "y", "vx", "vy")], axis=1)
        np.testing.assert_allclose(got, smoothed, atol=1e-5)  # float32 fields
        if chunk < 120:  # never more than the lag's scans and one chunk held
            assert max(most) <= int(lag / period) + 1 + chunk


def test_a_track_promoted_within_the_lag_is_a_person_from_its_first_confirmed_scan():
    n = 30
    stamps = 1_000_000_000 + np.arange(n, dtype=np.int64) * 100_000_000  # 10 Hz
    xs = {i: np.zeros((n, 4)) for i in (1, 2)}
    Ps = {i: np.tile(np.eye(4) * 0.01, (n, 1, 1)) for i in (1, 2)}
    status = {i: np.where(np.arange(n) < 3, STATUS_TENTATIVE, STATUS_CONFIRMED) for i in (1, 2)}
    cls = {1: np.full(n, CLASS_UNKNOWN), 2: np.full(n, CLASS_UNKNOWN)}
    cls[1][3 + 6 :] = CLASS_PERSON  # promoted 0.6 s after its first confirmed scan (scan 3)
    cls[2][3 + 15 :] = CLASS_PERSON  # promoted 1.5 s after it
    block = block_of(stamps, [[1, 2]] * n, xs, Ps, cls, status)
    _, items = run_buffer(stamps, block, 1.0, 4)
    one, two = items[items["id"] == 1], items[items["id"] == 2]
    assert (one["classification"][3:] == CLASS_PERSON).all()  # from the first confirmed scan
    assert (one["classification"][:3] == CLASS_UNKNOWN).all()  # tentative rows are left as they were
    assert (two["classification"][:18] == CLASS_UNKNOWN).all() and (two["classification"][18:] == CLASS_PERSON).all()


def test_promoted_within_lag_by_hand():
    never = np.iinfo(np.int64).max
    t = np.array([10, 12, 14, 16, 10, 30])
    confirmed = np.array([10, 10, 10, 10, 10, never])
    person = np.array([14, 14, 14, 14, 25, 30])
    assert H.promoted_within_lag(t, confirmed, person, 5).tolist() == [True, True, False, False, False, False]


def test_a_lag_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match="not positive"):
        H.Hindsight(0.0, Q, Q)


# ------------------------------------------------------------------------------------ where it applies


@pytest.fixture(scope="module")
def hall(tmp_path_factory):
    from datmo_cli.logs import mcapio
    from datmo_cli.passes.simulated import write_simulation
    from datmo_cli.sim.simulate import Simulation

    path = tmp_path_factory.mktemp("hindsight") / "hall.mcap"
    with mcapio.LogWriter(path, force=True) as writer:
        write_simulation(writer, Simulation("hall", seed=0, duration=20.0))
    return path


def decoded(payloads: list[bytes]) -> np.ndarray:
    from datmo_cli.logs import types
    from datmo_cli.report import decode_channel

    return decode_channel(types.TRACKS, payloads).items["tracks"]


def tracks_of(path):
    from datmo_cli.logs import mcapio

    return mcapio.read_messages(path, mcapio.TOPIC_TRACKS)[1]


@pytest.mark.slow
def test_datmo_run_smooths_and_says_so_the_live_stages_stay_causal(tmp_path, hall):
    from datmo_cli.live.messages import Stages
    from datmo_cli.logs import mcapio
    from datmo_cli.passes import pipeline
    from datmo_cli.passes.config import DatmoConfig

    smooth, causal = tmp_path / "smooth.mcap", tmp_path / "causal.mcap"
    pipeline.process_file(hall, smooth)
    pipeline.process_file(hall, causal, config=DatmoConfig().replace(track={"hindsight_lag": 0.0}))
    params = json.loads(mcapio.summary(smooth).metadata["datmo.params"]["hindsight"])
    assert params == {"used": True, "lag_s": 1.0}
    assert json.loads(mcapio.summary(causal).metadata["datmo.params"]["hindsight"]) == {"used": False, "lag_s": 0.0}
    a, b = tracks_of(smooth), tracks_of(causal)
    assert len(a) == len(b) == mcapio.summary(hall).topics()[mcapio.TOPIC_SCAN].count
    assert a != b
    # the live stages (datmo play, record --live, node) give the causal tracks, whatever the lag
    run = mcapio.read_run(hall)
    live = Stages(None, run.geometry, DatmoConfig())
    got = []
    for k in range(0, len(run), 16):
        part = type(run)(run.stamps[k : k + 16], run.ranges[k : k + 16], run.geometry)
        got += [m.payload for m in live.messages(part) if m.topic == mcapio.TOPIC_TRACKS]
    fields = ["id", "x", "y", "vx", "vy", "classification", "status"]  # the live stages keep the covariance
    assert np.array_equal(decoded(got)[fields], decoded(b)[fields])
    assert not np.array_equal(decoded(a)[fields], decoded(b)[fields])


@pytest.mark.slow
def test_hindsight_outputs_are_the_same_whatever_the_blocks(tmp_path, hall):
    from datmo_cli.passes import pipeline
    from datmo_cli.passes.stage_files import track_file

    pipeline.process_file(hall, tmp_path / "a.mcap", block_scans=1024)
    pipeline.process_file(hall, tmp_path / "b.mcap", block_scans=7)
    track_file(tmp_path / "a.mcap", tmp_path / "c.mcap", block_scans=3)  # from the log's features
    assert tracks_of(tmp_path / "a.mcap") == tracks_of(tmp_path / "b.mcap") == tracks_of(tmp_path / "c.mcap")


def test_nothing_is_smoothed_across_a_reset():
    """A track re-initialised (its state and covariance started anew, as at a merge or a re-acquisition that
    resets it) is smoothed as two tracks: the rows before the reset as if the track had died there."""
    a = filtered_track(20, seed=5)
    b = filtered_track(15, seed=6)
    shift = a[0][-1] + 200_000_000 - b[0][0]
    stamps = np.concatenate([a[0], b[0] + shift])
    xs = np.concatenate([a[1], b[1] + [3.0, -2.0, 0.0, 0.0]])  # a jump of 3.6 m with a fresh covariance
    Ps = np.concatenate([a[2], b[2]])
    rows = np.arange(35)
    got, _ = H.smooth(stamps, np.full(35, 4), xs, Ps, np.full(35, Q), rows, 10**9, q_most=Q)
    alone, _ = H.smooth(a[0], np.full(20, 4), a[1], a[2], np.full(20, Q), np.arange(20), 10**9, q_most=Q)
    np.testing.assert_allclose(got[:20], alone, atol=1e-9)
    joined, _ = H.smooth(stamps, np.full(35, 4), xs, Ps, np.full(35, Q), rows, 10**9, q_most=1e9)  # no reset seen
    assert np.abs(joined[19, 2:] - alone[19, 2:]).max() > 1.0  # it would have spread the jump into a speed


def test_the_written_out_matrix_algebra_equals_numpys():
    """The reference's batched products, SPD solve and eigenvalue test (plain products and sums, the same bits on
    every CPU, as the kernel's) give what numpy's matmul, linalg.solve and eigvalsh give, to rounding."""
    rng = np.random.default_rng(0)
    a, b, x = rng.normal(size=(60, 4, 4)), rng.normal(size=(60, 4, 4)), rng.normal(size=(60, 4))
    np.testing.assert_allclose(rt.rts_mm(a, b), a @ b, atol=1e-12)
    np.testing.assert_allclose(rt.rts_mv(a, x), np.einsum("nij,nj->ni", a, x), atol=1e-12)
    spd = a @ np.transpose(a, (0, 2, 1)) + 0.1 * np.eye(4)
    np.testing.assert_allclose(rt.rts_solve_spd(spd, b), np.linalg.solve(spd, b), rtol=1e-8, atol=1e-9)
    sym, limit = 0.5 * (a + np.transpose(a, (0, 2, 1))), rng.normal(size=60)
    assert (rt.rts_largest_eigenvalue_above(sym, limit) == (np.linalg.eigvalsh(sym)[:, -1] > limit)).all()


def buffer_of_tracks(seed: int, n_tracks: int = 6, n_scans: int = 90):
    """A buffer of track rows as Hindsight holds them (rows in scan order, tracks born and dying, at a few
    steps), float32 states and covariances as the Track elements carry them, some rows re-initialised (a
    covariance far wider than its prediction), person steps with a larger q: (t_ns, ids, state, cov, q)."""
    rng = np.random.default_rng(seed)
    t = 10**9 + np.cumsum(rng.choice([26_666_667, 26_666_666, 53_333_333], n_scans))
    born, dies = rng.integers(0, n_scans, n_tracks), rng.integers(0, n_scans, n_tracks)
    rows = [(t[k], i) for k in range(n_scans) for i in range(n_tracks) if min(born[i], dies[i]) <= k <= dies[i] + 20]
    t_ns, ids = np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], np.int64)
    state = rng.normal(size=(len(rows), 4)).astype(np.float32).astype(np.float64)
    a = rng.normal(size=(len(rows), 4, 4)) * 0.1
    cov = (a @ np.transpose(a, (0, 2, 1)) + 0.01 * np.eye(4)).astype(np.float32).astype(np.float64)
    cov[rng.random(len(rows)) < 0.05] *= 1000.0
    cov[rng.random(len(rows)) < 0.1] = np.diag(rng.uniform(0.01, 1.0, 4))  # fresh tracks: exact zeros
    q = np.where(rng.random(len(rows)) < 0.3, 4.0, Q)
    return t_ns, ids, state, cov, q


@pytest.mark.parametrize("seed", range(6))
def test_the_kernel_gives_the_references_bits(seed):
    """smooth (one compiled call, _rts.smooth_rows) gives reference_smooth's numbers bit for bit, states and
    covariances, resets and all, for every row or the first ones alone."""
    from datmo_cli.tracking import _rts

    t_ns, ids, state, cov, q = buffer_of_tracks(seed)
    for rows in (np.arange(len(t_ns)), np.arange(len(t_ns) * 2 // 3)):
        for lag_ns in (10**9, 10**8):
            want, want_cov = rt.reference_smooth(t_ns, ids, state, cov, q, rows, lag_ns, q_most=4.0)
            got, got_cov = H.smooth(t_ns, ids, state, cov, q, rows, lag_ns, q_most=4.0)
            assert np.array_equal(got, want) and np.array_equal(got_cov, want_cov)
            lean, none = H.smooth(t_ns, ids, state, cov, q, rows, lag_ns, covariance=False, q_most=4.0)
            assert np.array_equal(lean, want) and none is None
            nxt, prv = H.chains(ids, t_ns)
            direct = _rts.smooth_rows(t_ns, nxt, prv, state, cov, q, rows, lag_ns, True, 4.0, H.RESET_TOLERANCE)
            assert np.array_equal(direct[0], want) and np.array_equal(direct[1], want_cov)
    nxt, _ = H.chains(ids, t_ns)
    assert len(rt.rts_gains(t_ns, state, cov, q, nxt, 4.0)[3])  # the case holds resets


def test_the_kernels_algebra_is_the_references():
    """_rts's product, process noise and RTS terms of one step give the reference's (rts_mm, rts_process_noise,
    rts_gains) bit for bit."""
    from datmo_cli.tracking import _rts

    t_ns, ids, state, cov, q = buffer_of_tracks(7)
    out = np.zeros((4, 4))
    for k in range(20):
        _rts._mm(cov[k], cov[k + 1], out)
        assert np.array_equal(out, rt.rts_mm(cov[k : k + 1], cov[k + 1 : k + 2])[0])
    for dt in (0.026666667, 0.053333333, 0.1, 1.7):
        _rts._noise(dt, dt**3, dt**4, 2.0, out)
        assert np.array_equal(out, rt.rts_process_noise(np.array([dt]), np.array([2.0]))[0])
    nxt, _ = H.chains(ids, t_ns)
    C, xp, Pp, reset = rt.rts_gains(t_ns, state, cov, q, nxt, 4.0)
    work = RtsWork(*(np.zeros((4, 4)) for _ in RtsWork._fields))
    c, x, p = np.zeros((4, 4)), np.zeros(4), np.zeros((4, 4))
    for r in np.flatnonzero(nxt >= 0)[:200]:
        n = nxt[r]
        dt = float(t_ns[n] - t_ns[r]) * 1e-9
        args = (dt, dt**3, dt**4, cov[r], state[r], cov[n], q[r], 4.0, H.RESET_TOLERANCE, c, x, p, work)
        assert _rts._gain(*args) == (r in reset)
        assert np.array_equal(c, C[r]) and np.array_equal(x, xp[n]) and np.array_equal(p, Pp[n])
