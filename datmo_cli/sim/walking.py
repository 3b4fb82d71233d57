"""The walking model of docs/method.md §6.1 (after Alexander 2001), as leg circles at the scanner's height.

A person's body moves along its path at constant speed v. Feet land on footprints along the path, one
step length s = 2 l sin(theta) apart, alternately left and right of the path by d_S / 2 (d_S: the
distance between the legs' paths, the paper's shoulder width). During step k (body arc length u in
[k s, (k+1) s)) footprint k carries the stance leg while the other leg swings from footprint k-1 to
k+1. The swing starts only after a short double-support phase: one foot is set down just before the
other lifts. When the walker stops, its feet come side by side (d_S apart across its heading) over
`settle` seconds, and part again over the last `settle` seconds before it walks on.
World frame, metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datmo_cli.base import libm

from .paths import Timeline


@dataclass(frozen=True)
class Gait:
    """Walking parameters: metres and radians."""

    leg_length: float = 0.9  # l
    swing_angle: float = np.radians(22.0)  # theta
    shoulder_width: float = 0.3  # d_S, distance between the legs' paths
    leg_radius: float = 0.10  # leg circle at the scanner's height
    double_support: float = 0.15  # fraction of a step with both feet down
    step: float | None = None  # step length override, m
    settle: float = 0.5  # s to bring the feet together after stopping (and apart before starting)

    @property
    def step_length(self) -> float:
        """s = 2 l sin(theta), unless given directly."""
        return self.step if self.step is not None else 2.0 * self.leg_length * libm.sin(self.swing_angle)


def footprints(timeline: Timeline, gait: Gait, index: np.ndarray) -> np.ndarray:
    """(n, 2) world positions of footprints `index` (even: left foot, odd: right foot)."""
    s = gait.step_length
    index = np.asarray(index)
    # a little ahead of mid-step so that, averaged over a step, the legs' midpoint is the body's position
    centre, d = timeline.point_at((index + 0.5 + gait.double_support / 2) * s)
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1)  # left of the direction of travel
    side = np.where(index % 2 == 0, 0.5, -0.5) * gait.shoulder_width
    return centre + side[:, None] * normal


def legs(timeline: Timeline, gait: Gait, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) leg centres, each (n, 2), world frame, at times `t` (s)."""
    s = gait.step_length
    u = timeline.arclength(t)
    k = np.floor(u / s).astype(np.int64)
    phase = u / s - k
    stance = footprints(timeline, gait, k)
    lifted = footprints(timeline, gait, k - 1)
    landing = footprints(timeline, gait, k + 1)
    ds = gait.double_support
    x = np.clip((phase - ds) / (1.0 - ds), 0.0, 1.0)
    g = 0.5 - 0.5 * libm.cos(np.pi * x)  # the swing foot starts and stops gently
    swing = lifted + g[:, None] * (landing - lifted)
    left_stance = (k % 2 == 0)[:, None]
    left, right = np.where(left_stance, stance, swing), np.where(left_stance, swing, stance)
    since, until = timeline.standing(t)
    rest = np.minimum(since, until)  # inf while walking
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = np.where(np.isfinite(rest), np.clip(rest / gait.settle, 0.0, 1.0) if gait.settle > 0 else 1.0, 0.0)
    beta = beta[:, None]
    if np.any(beta > 0):
        body, heading = timeline.position(t), timeline.heading(t)
        normal = np.stack([-libm.sin(heading), libm.cos(heading)], 1) * (gait.shoulder_width / 2)
        left = (1 - beta) * left + beta * (body + normal)
        right = (1 - beta) * right + beta * (body - normal)
    return left, right
