"""A scan's measurements as the compiled step takes them, and the frames they move between.

Features (circles, blobs, lines and, with a leg detector, leg candidates; sensor frame: x forward, y left, m;
beam indices inclusive) become measurements by the paper's rule (paper_measurements) or with the detector's legs
(learned_measurements): x, y, size (m), kind (K_*, measurements.KIND_*'s), legs (M, 4: the two legs of a pair,
else nan), the raw leg candidates (L, RAW_COLS) and each measurement's leg probability. `moved` takes them to the
tracking frame; `to_sensor` takes a tracking-frame point back to the sensor frame. References:
tests/reference_tracking.reference_measurements and moved.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from . import _kernels
from .bundles import Legs, ScanMeasurements
from .state import P_LEG_RADIUS_MAX, P_LEG_THRESHOLD

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

K_PERSON, K_LEG, K_CIRCLE, K_RECT, K_BLOB = 0, 1, 2, 3, 4
# the raw leg candidates of a scan, (L, RAW_COLS): x, y (m), width (m), leg probability (0 without a detector),
# cover: -1 for a strong candidate (a leg), else the index of the measurement made of the weaker candidate's beams
R_X, R_Y, R_W, R_P, R_COVER = 0, 1, 2, 3, 4
RAW_COLS = 5
# the leg probability of a leg candidate found on the background or carried: a candidate (its hit moves a track's
# evidence), and not a leg
NOT_A_LEG = 1e-6
# ... and of one on carried beams: a part of the robot, whose hit takes all of a track's evidence
CARRIED_LEG = 2e-6


@njit(cache=True)
def paper_measurements(circles, blobs, lines, prm):
    """One scan's measurements by the paper's rule (reference: tests/reference_tracking.reference_measurements,
    learned=False), sensor frame: a ScanMeasurements whose raw leg candidates are (L, RAW_COLS: x, y, size, 0, -1)
    and prob zeros. circles, blobs, lines: bundles.Circles, Blobs, Lines (m, beam indices inclusive; the paper's
    rule reads no beams)."""
    found = _kernels.measurements(
        (circles.x, circles.y, circles.radius),
        (blobs.x, blobs.y, blobs.size, blobs.kind),
        (lines.segment, lines.x_ini, lines.y_ini, lines.x_end, lines.y_end),
        prm,
    )
    lx, ly, ls = found.leg_x, found.leg_y, found.leg_size
    raw = np.zeros((len(lx), RAW_COLS))
    for i in range(len(lx)):
        raw[i, R_X], raw[i, R_Y], raw[i, R_W], raw[i, R_COVER] = lx[i], ly[i], ls[i], -1.0
    return ScanMeasurements(found.x, found.y, found.size, found.kind, found.legs, raw, np.zeros(len(found.x)))


@njit(cache=True)
def learned_measurements(circles, blobs, lines, legs, prm):
    """One scan's measurements with a leg detector's legs (reference_measurements, learned=True): the candidates
    of probability >= the leg threshold (P_LEG_THRESHOLD, the model's) not on the beams of a circle wider than
    leg_radius_max are legs (strong); the others (weak) are measured as what covers their beams, which takes their
    probability. circles, blobs, lines as paper_measurements'; legs: bundles.Legs. Returns a ScanMeasurements
    whose raw (L, RAW_COLS) holds every candidate, strong ones first, each with its probability and, for a weak
    one, the measurement covering it. The thresholds compare in float32, as numpy compares the features' float32
    fields with a Python float."""
    gfirst, glast, gx, gy, gw, gp = legs.first, legs.last, legs.x, legs.y, legs.width, legs.probability
    thr = np.float32(prm[P_LEG_THRESHOLD])
    rmax = np.float32(prm[P_LEG_RADIUS_MAX])
    strong = np.empty(len(gx), np.bool_)
    for i in range(len(gx)):
        s = np.float32(gp[i]) >= thr
        for q in range(len(circles.radius)):
            if np.float32(circles.radius[q]) > rmax and not (
                glast[i] < circles.first[q] or gfirst[i] > circles.last[q]
            ):
                s = False  # type: ignore[assignment]  # numba: numpy and Python bools are one type
        strong[i] = s
    weak = ~strong
    found = _kernels.learned_measurements(
        circles,
        blobs,
        lines,
        Legs(gfirst[strong], glast[strong], gx[strong], gy[strong], gw[strong], gp[strong]),
        (gfirst[weak], glast[weak], gp[weak]),
        prm,
    )
    cover = found.cover
    raw = np.empty((len(gx), RAW_COLS))
    q = 0
    for i in range(len(gx)):
        if strong[i]:
            raw[q, R_X], raw[q, R_Y], raw[q, R_W], raw[q, R_P], raw[q, R_COVER] = gx[i], gy[i], gw[i], gp[i], -1.0
            q += 1
    w = 0
    for i in range(len(gx)):
        if not strong[i]:
            raw[q, R_X], raw[q, R_Y], raw[q, R_W], raw[q, R_P], raw[q, R_COVER] = gx[i], gy[i], gw[i], gp[i], cover[w]
            q += 1
            w += 1
    return ScanMeasurements(found.x, found.y, found.size, found.kind, found.legs, raw, found.prob)


@njit(cache=True)
def moved(mx, my, mlegs, raw, px, py, pc, ps):
    """Measurements (mx, my), their legs and the raw leg candidates in the tracking frame of a sensor at
    (px, py) with heading cos/sin (pc, ps): new arrays (reference: tests/reference_tracking.moved)."""
    x = pc * mx - ps * my + px
    y = ps * mx + pc * my + py
    legs = mlegs.copy()
    for i in range(len(mlegs)):
        for c in (0, 2):
            legs[i, c] = pc * mlegs[i, c] - ps * mlegs[i, c + 1] + px
            legs[i, c + 1] = ps * mlegs[i, c] + pc * mlegs[i, c + 1] + py
    r = raw.copy()
    for i in range(len(raw)):
        r[i, 0] = pc * raw[i, 0] - ps * raw[i, 1] + px
        r[i, 1] = ps * raw[i, 0] + pc * raw[i, 1] + py
    return x, y, legs, r


@njit(cache=True)
def to_sensor(x, y, has_pose, pose):
    """A tracking-frame point in the sensor frame of `pose` (itself without a pose)."""
    if not has_pose:
        return x, y
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx, dy = x - pose[0], y - pose[1]
    return c * dx + s * dy, -s * dx + c * dy
