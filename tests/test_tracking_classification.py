"""Classification rules of docs/method.md §6: classes from measurement kinds, and the mobility states."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.tracking.measurements import KIND_BLOB, KIND_CIRCLE, KIND_LEG, KIND_PERSON, KIND_RECT, N_KINDS
from datmo_cli.tracking.params import TrackingParams
from tests.reference_tracking import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
    MOBILITY_STATIC,
    MOBILITY_UNDEFINED,
    classify,
    classify_tracks,
    mobility,
)

pytestmark = pytest.mark.unit

P = TrackingParams()


def votes(**counts: int) -> np.ndarray:
    v = np.zeros((1, N_KINDS), np.int64)
    names = {"person": KIND_PERSON, "leg": KIND_LEG, "circle": KIND_CIRCLE, "rect": KIND_RECT, "blob": KIND_BLOB}
    for name, n in counts.items():
        v[0, names[name]] = n
    return v


def one(v: np.ndarray, walking: bool = False, moving: bool = False) -> int:
    return int(classify(v, np.array([walking]), np.array([moving]), P)[0])


def test_classes_from_measurement_kinds():
    assert one(votes(person=8, leg=2), walking=True, moving=True) == CLASS_PERSON
    assert one(votes(person=8, leg=2), walking=False, moving=True) == CLASS_UNKNOWN  # no walking pattern
    assert one(votes(circle=9, blob=1)) == CLASS_CIRCLE_OBJECT
    assert one(votes(rect=5, circle=1)) == CLASS_RECTANGULAR_OBJECT
    assert one(votes(blob=5)) == CLASS_UNKNOWN
    assert one(votes(leg=10)) == CLASS_CIRCLE_OBJECT  # a lone small circle in place: a post, a bin
    assert one(votes(leg=10), moving=True) == CLASS_UNKNOWN  # a lone moving leg is not yet anything


def _mob(
    previous: int, age: float, size: float = 0.3, moved: float = 0.0, speed: float = 0.0, confirmed: bool = True
) -> int:
    return int(
        mobility(
            np.array([previous], np.uint8),
            np.array([age]),
            np.array([size]),
            np.array([moved]),
            np.array([speed]),
            np.array([confirmed]),
            P,
        )[0]
    )


def test_mobility_states():
    assert _mob(MOBILITY_UNDEFINED, age=0.2) == MOBILITY_UNDEFINED  # X: small and young
    assert _mob(MOBILITY_UNDEFINED, age=0.2, size=2.0) == MOBILITY_STATIC  # larger than d_max
    assert _mob(MOBILITY_UNDEFINED, age=P.undefined_window + 0.1) == MOBILITY_STATIC  # seen not moving
    assert _mob(MOBILITY_STATIC, age=5, moved=1.0, speed=0.8) == MOBILITY_DYNAMIC
    assert _mob(MOBILITY_UNDEFINED, age=5, moved=1.0, speed=0.8, confirmed=False) != MOBILITY_DYNAMIC
    assert _mob(MOBILITY_DYNAMIC, age=50, moved=0.0, speed=0.0) == MOBILITY_DYNAMIC  # dynamic for ever
    assert _mob(MOBILITY_DYNAMIC, age=50, size=3.0) == MOBILITY_DYNAMIC


def test_fused_kernel_matches_the_rules():
    rng = np.random.default_rng(2)
    K = 500
    v = rng.integers(0, 4, (K, N_KINDS)) * (rng.random((K, N_KINDS)) < 0.5)
    walking, confirmed = rng.random(K) < 0.5, rng.random(K) < 0.7
    prev = rng.integers(0, 3, K).astype(np.uint8)
    age, size = rng.uniform(0, 3, K), rng.uniform(0, 2, K)
    moved, speed = rng.uniform(0, 1, K), rng.uniform(0, 1, K)
    mob = mobility(prev, age, size, moved, speed, confirmed, P)
    cls = classify(v, walking, mob == MOBILITY_DYNAMIC, P)
    kcls, kmob = classify_tracks(
        v.astype(np.int64),
        walking,
        prev,
        age,
        size,
        moved,
        speed,
        confirmed,
        P.person_votes,
        P.d_max,
        P.undefined_window,
        P.moving_distance,
        P.moving_speed,
    )
    assert np.array_equal(kmob, mob)
    assert np.array_equal(kcls, cls)
