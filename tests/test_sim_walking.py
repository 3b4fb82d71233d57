"""Paths and the walking model (docs/method.md §6.1): step length, leg alternation, body speed, pauses, towing."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.sim._kernels import tow
from datmo_cli.sim.paths import PathSpec, Timeline
from datmo_cli.sim.walking import Gait, footprints, legs

pytestmark = pytest.mark.unit

STRAIGHT = PathSpec(np.array([[0.0, 0.0], [100.0, 0.0]]), speed=1.3)


def test_path_timing_pauses_and_velocity():
    spec = PathSpec(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]]), speed=2.0, pauses={1: 1.5}, start_time=1.0)
    tl = Timeline(spec, 100.0)
    t = np.array([0.0, 0.9, 2.0, 3.0, 3.5, 4.5, 5.25, 6.0, 50.0])
    np.testing.assert_allclose(
        tl.position(t), [[0, 0], [0, 0], [2, 0], [4, 0], [4, 0], [4, 0], [4, 1.5], [4, 3], [4, 3]]
    )
    np.testing.assert_allclose(
        tl.velocity(t), [[0, 0], [0, 0], [2, 0], [0, 0], [0, 0], [0, 2], [0, 2], [0, 0], [0, 0]], atol=1e-12
    )
    np.testing.assert_allclose(tl.heading(np.array([0.0, 3.5, 5.0, 50.0])), [0, 0, np.pi / 2, np.pi / 2])


def test_looping_path_returns_to_start():
    spec = PathSpec(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), speed=1.0, loop=True)
    tl = Timeline(spec, 30.0)
    period = 2 + 2 + 2 * np.sqrt(2)
    np.testing.assert_allclose(tl.position(np.array([period, 2 * period + 1.0])), [[0, 0], [1, 0]], atol=1e-9)


def test_bad_paths_are_refused():
    with pytest.raises(ValueError):
        Timeline(PathSpec(np.array([[0.0, 0.0], [0.0, 0.0]]), 1.0), 10.0)
    with pytest.raises(ValueError):
        Timeline(PathSpec(np.array([[0.0, 0.0], [1.0, 0.0]]), 0.0), 10.0)


def test_step_length_is_two_l_sin_theta():
    g = Gait(leg_length=0.9, swing_angle=np.radians(25.0))
    assert g.step_length == pytest.approx(2 * 0.9 * np.sin(np.radians(25.0)))
    tl = Timeline(STRAIGHT, 80.0)
    f = footprints(tl, g, np.arange(10))
    np.testing.assert_allclose(np.diff(f[:, 0]), g.step_length)  # along the path
    np.testing.assert_allclose(np.abs(np.diff(f[:, 1])), g.shoulder_width)  # alternately left and right
    assert np.all(f[::2, 1] > 0) and np.all(f[1::2, 1] < 0)


def test_legs_alternate_between_stance_and_swing():
    g = Gait()
    tl = Timeline(STRAIGHT, 80.0)
    dt = 0.01
    t = np.arange(0, 20, dt)
    left, right = legs(tl, g, t)
    vl = np.hypot(*np.diff(left, axis=0).T) / dt
    vr = np.hypot(*np.diff(right, axis=0).T) / dt
    assert not np.any((vl > 1e-6) & (vr > 1e-6))  # never both feet off the ground
    both_down = (vl < 1e-6) & (vr < 1e-6)
    assert 0.05 < both_down.mean() < 0.3  # short double-support phases
    moving = np.where(vl > 1e-6, 1, np.where(vr > 1e-6, 2, 0))
    swings = moving[moving > 0]
    changes = swings[np.flatnonzero(np.diff(swings)) + 1]
    assert len(changes) > 20 and np.all(np.diff(changes) != 0)  # left, right, left, ...
    step_time = g.step_length / STRAIGHT.speed
    assert len(changes) + 1 == pytest.approx(20 / step_time, abs=2)
    # a swinging foot moves two step lengths while the body moves one
    assert vl.max() > 2 * STRAIGHT.speed


def test_mean_body_speed_and_legs_around_the_body():
    g = Gait(shoulder_width=0.3)
    tl = Timeline(STRAIGHT, 80.0)
    t = np.linspace(0, 30, 3001)
    body = tl.position(t)
    assert (body[-1, 0] - body[0, 0]) / 30 == pytest.approx(1.3)
    left, right = legs(tl, g, t)
    mid = (left + right) / 2
    assert np.abs(mid[:, 0] - body[:, 0]).max() < 0.5 * g.step_length
    np.testing.assert_allclose(np.abs(left[:, 1] - right[:, 1]), 0.3, atol=1e-12)
    assert ((left[:, 0] + right[:, 0]) / 2 - body[:, 0]).mean() == pytest.approx(0.0, abs=0.005)


def test_feet_come_together_during_a_pause_and_at_the_ends():
    spec = PathSpec(np.array([[0.0, 0.0], [3.0, 0.0], [6.0, 0.0]]), speed=1.0, pauses={1: 2.0}, start_time=1.0)
    tl = Timeline(spec, 20.0)
    g = Gait(shoulder_width=0.3, settle=0.5)
    t = np.array([0.0, 0.4, 4.5, 5.0, 5.5, 12.0])  # before the start, standing at waypoint 1, after the end
    left, right = legs(tl, g, t)
    np.testing.assert_allclose(left, tl.position(t) + [0.0, 0.15], atol=1e-12)
    np.testing.assert_allclose(right, tl.position(t) - [0.0, 0.15], atol=1e-12)
    # and move continuously in and out of the pause (no jumps between 10 ms samples)
    ts = np.arange(3.0, 7.0, 0.01)
    left, right = legs(tl, g, ts)
    assert np.hypot(*np.diff(left, axis=0).T).max() < 0.05 and np.hypot(*np.diff(right, axis=0).T).max() < 0.05


def test_standing_intervals():
    spec = PathSpec(np.array([[0.0, 0.0], [3.0, 0.0], [6.0, 0.0]]), speed=1.0, pauses={1: 2.0}, start_time=1.0)
    since, until = Timeline(spec, 20.0).standing(np.array([0.5, 2.0, 4.5, 10.0]))
    np.testing.assert_allclose(since, [np.inf, np.inf, 0.5, 1.0])
    np.testing.assert_allclose(until, [0.5, np.inf, 1.5, np.inf])


def test_towed_load_keeps_the_wire_length():
    t = np.arange(0, 20, 0.01)
    leader = np.stack([t, 0.5 * np.sin(t / 3)], 1)
    track = tow(leader, np.array([-2.0, 0.0]), 2.0)
    dist = np.hypot(*(leader - track).T)
    assert np.all(dist <= 2.0 + 1e-9) and dist[100:].min() > 1.99
    still = tow(np.zeros((5, 2)), np.array([1.0, 0.0]), 2.0)  # slack wire: the load stays put
    np.testing.assert_allclose(still, [[1.0, 0.0]] * 5)
