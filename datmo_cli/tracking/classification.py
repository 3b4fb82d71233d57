"""Classification (method.md §6): class from the kinds of measurement a track was fed, and mobility.

These are the paper's rules (`--leg-model paper`). With the learned leg detector (the default), the person
rule is the leg detector's evidence over a track's recent hits instead, walking not required: see
tracker.Tracker and the README's "People" section. Mobility is the same in both.

Classes (Track.msg): person (leg measurements and the walking pattern), circle object, rectangular object,
unknown. Mobility: 0 static, 1 dynamic, X (2) undefined:
- static when its extent is larger than d_max, or when the tracker sees it not moving after the
  undefined window;
- dynamic set only here, by the tracker's evidence of motion, and kept for ever;
- X while younger than the undefined window (small circles and blobs may be legs or something entering).
"""

from __future__ import annotations

import numpy as np

from .measurements import KIND_BLOB, KIND_CIRCLE, KIND_LEG, KIND_PERSON, KIND_RECT
from .params import TrackingParams

CLASS_UNKNOWN, CLASS_PERSON, CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT = 0, 1, 2, 3
MOBILITY_STATIC, MOBILITY_DYNAMIC, MOBILITY_UNDEFINED = 0, 1, 2


def classify(votes: np.ndarray, walking: np.ndarray, moving: np.ndarray, params: TrackingParams) -> np.ndarray:
    """Class of each track from `votes` (K, N_KINDS: hits per measurement kind), `walking` (the walking
    pattern was seen) and `moving` (mobility is dynamic).

    Legs: a person once walking is seen; a pair of legs that never walked stays unknown; a lone small
    circle that does not move is a circle object (a bench support, a bin). Otherwise the kind with most
    hits: circles give circle objects, lines rectangular objects, blobs unknown."""
    total = votes.sum(axis=1)
    legs = votes[:, KIND_PERSON] + votes[:, KIND_LEG]
    leggy = legs >= params.person_votes * np.maximum(total, 1)
    shape = np.stack([votes[:, KIND_CIRCLE], votes[:, KIND_RECT], votes[:, KIND_BLOB]], axis=1)
    by_shape = np.array([CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN])[np.argmax(shape, axis=1)]
    by_shape = np.where(shape.sum(axis=1) > 0, by_shape, CLASS_UNKNOWN)
    lone_static_leg = (votes[:, KIND_PERSON] == 0) & ~moving
    leg_class = np.where(walking & (votes[:, KIND_PERSON] > 0), CLASS_PERSON,
                         np.where(lone_static_leg, CLASS_CIRCLE_OBJECT, CLASS_UNKNOWN))
    return np.where(leggy, leg_class, by_shape).astype(np.uint8)


def mobility(previous: np.ndarray, age_s: np.ndarray, size: np.ndarray, displacement: np.ndarray,
             speed: np.ndarray, confirmed: np.ndarray, params: TrackingParams) -> np.ndarray:
    """New mobility of each track: `previous` mobility, age (s), largest extent seen (m), distance from
    where it was first seen (m), filtered speed (m/s), and whether it is confirmed."""
    dynamic = (previous == MOBILITY_DYNAMIC) | (confirmed & (displacement > params.moving_distance)
                                                & (speed > params.moving_speed))
    static = (size > params.d_max) | (age_s >= params.undefined_window)
    out = np.where(static, MOBILITY_STATIC, MOBILITY_UNDEFINED)
    return np.where(dynamic, MOBILITY_DYNAMIC, out).astype(np.uint8)
