"""Waypoint paths as functions of time: piecewise-linear motion at constant speed, with pauses.

World frame, metres, seconds, radians. A path starts at its first waypoint at `start_time`, stands there
before, walks each leg at `speed`, stands `pauses[i]` seconds on reaching waypoint i, and stands at the
last waypoint at the end (or, with `loop`, walks back to the first and starts over).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from datmo_cli.base import libm


@dataclass(frozen=True)
class PathSpec:
    """A path as a scene file gives it."""

    points: np.ndarray  # (K, 2) waypoints, world frame, m
    speed: float  # m/s while moving
    pauses: dict[int, float] = field(default_factory=dict)  # waypoint index -> standing time, s
    start_time: float = 0.0  # s after the run's start
    loop: bool = False


class Timeline:
    """A PathSpec unrolled over [0, t_end]: knots (time, position, arc length) and its moving legs."""

    def __init__(self, spec: PathSpec, t_end: float) -> None:
        pts = np.asarray(spec.points, np.float64)
        k = len(pts)
        steps = np.hypot(*np.diff(np.vstack([pts, pts[:1]]) if spec.loop else pts, axis=0).T)
        if k < 2 or spec.speed <= 0 or np.any(steps == 0):
            raise ValueError("a path needs two or more distinct consecutive waypoints and a positive speed")
        times, xy, arc = [spec.start_time], [pts[0]], [0.0]
        t, u, i = spec.start_time, 0.0, 0
        while True:
            j = i + 1
            if j == k:
                if not spec.loop:
                    break
                j = 0
            step = float(np.hypot(*(pts[j] - pts[i % k])))
            t += step / spec.speed
            u += step
            times.append(t)
            xy.append(pts[j])
            arc.append(u)
            pause = spec.pauses.get(j, 0.0)
            if pause > 0:
                t += pause
                times.append(t)
                xy.append(pts[j])
                arc.append(u)
            i = j
            if t > t_end:
                break
        self.t = np.array(times)
        self.xy = np.array(xy)
        self.u = np.array(arc)
        moving = np.diff(self.u) > 0
        self._leg_knot = np.flatnonzero(moving)  # knot index where each moving leg starts
        d = self.xy[self._leg_knot + 1] - self.xy[self._leg_knot]
        self._leg_dir = d / np.hypot(d[:, 0], d[:, 1])[:, None]
        self._leg_u0 = self.u[self._leg_knot]
        self._leg_xy0 = self.xy[self._leg_knot]
        self.speed = spec.speed

    def _interval(self, t: np.ndarray) -> np.ndarray:
        return np.searchsorted(self.t, t, side="right") - 1

    def position(self, t: np.ndarray) -> np.ndarray:
        """(n, 2) positions at times `t` (s)."""
        t = np.asarray(t, np.float64)
        return np.stack([np.interp(t, self.t, self.xy[:, 0]), np.interp(t, self.t, self.xy[:, 1])], axis=1)

    def arclength(self, t: np.ndarray) -> np.ndarray:
        """(n,) distance walked by time `t`, m."""
        return np.interp(np.asarray(t, np.float64), self.t, self.u)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """(n, 2) velocity, m/s (zero while standing)."""
        t = np.asarray(t, np.float64)
        out = np.zeros((len(t), 2))
        if len(self._leg_knot) == 0:
            return out
        idx = self._interval(t)
        ok = (idx >= 0) & (idx < len(self.t) - 1)
        ok[ok] &= self.u[idx[ok] + 1] > self.u[idx[ok]]
        leg = np.searchsorted(self._leg_knot, idx[ok])
        out[ok] = self._leg_dir[leg] * self.speed
        return out

    def heading(self, t: np.ndarray) -> np.ndarray:
        """(n,) direction of travel, rad; while standing, the direction of the last (or first) leg."""
        t = np.asarray(t, np.float64)
        if len(self._leg_knot) == 0:
            return np.zeros(len(t))
        idx = self._interval(t)
        leg = np.searchsorted(self._leg_knot, idx, side="right") - 1
        leg = np.clip(leg, 0, len(self._leg_knot) - 1)
        d = self._leg_dir[leg]
        return libm.arctan2(d[:, 1], d[:, 0])

    def standing(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(seconds since the walker last stopped, seconds until it moves again) at times `t`; both inf while
        it is moving, and inf before the start / after the end where there is no stop or start."""
        t = np.asarray(t, np.float64)
        moving = np.diff(self.u) > 0
        # standing intervals: before the first knot, every knot interval without motion, after the last knot
        starts = np.concatenate([[-np.inf], self.t[:-1][~moving], [self.t[-1]]])
        ends = np.concatenate([[self.t[0]], self.t[1:][~moving], [np.inf]])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        inside = (t >= starts[idx]) & (t <= ends[idx])
        since = np.where(inside, t - starts[idx], np.inf)
        until = np.where(inside, ends[idx] - t, np.inf)
        return since, until

    def _leg_at(self, u: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self._leg_u0, u, side="right") - 1, 0, len(self._leg_u0) - 1)

    def point_at(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(points (n, 2), unit directions (n, 2)) at arc lengths `u`; straight extrapolation past the ends."""
        u = np.asarray(u, np.float64)
        if len(self._leg_knot) == 0:
            return np.repeat(self.xy[:1], len(u), 0), np.tile([1.0, 0.0], (len(u), 1))
        leg = self._leg_at(u)
        d = self._leg_dir[leg]
        return self._leg_xy0[leg] + (u - self._leg_u0[leg])[:, None] * d, d
