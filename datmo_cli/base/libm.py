"""Trigonometry that gives the same bits on every x86-64 CPU: the C library's functions (Python's `math`), for
scalars and arrays, in radians.

numpy picks a SIMD loop for `np.sin`, `np.cos` and `np.arctan2` on float64 by the CPU it runs on: with AVX-512
it uses its SVML code, whose results differ from the C library's in the last bit or two; without, the C
library's. datmo's kernels (numba) call the C library's functions on every CPU. So Python-level code whose
results reach an output uses these instead of numpy's, and the outputs are the same on a CPU with AVX-512 and
without (tests/test_output_digests.py, tests/test_libm.py). The arrays this is used on are small (a scan's beam
angles, a few detections a scan): a loop over `math` costs microseconds there.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["arccos", "arctan2", "cos", "sin"]


def _apply1(fn: Any, x: Any) -> Any:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 0:
        return np.float64(fn(float(a)))
    flat = a.ravel()
    return np.fromiter(map(fn, flat.tolist()), np.float64, count=flat.size).reshape(a.shape)


def _sin(v: float) -> float:
    return math.sin(v) if math.isfinite(v) else math.nan  # math raises on inf, numpy gives nan


def _cos(v: float) -> float:
    return math.cos(v) if math.isfinite(v) else math.nan


def sin(x: Any) -> Any:
    """sin of radians, element-wise (the C library's); nan for inf."""
    return _apply1(_sin, x)


def cos(x: Any) -> Any:
    """cos of radians, element-wise (the C library's); nan for inf."""
    return _apply1(_cos, x)


def arccos(x: Any) -> Any:
    """acos in radians, element-wise (the C library's); nan outside [-1, 1]."""
    return _apply1(lambda v: math.acos(v) if -1.0 <= v <= 1.0 else math.nan, x)


def arctan2(y: Any, x: Any) -> Any:
    """atan2(y, x) in radians, element-wise with numpy's broadcasting (the C library's)."""
    ya, xa = np.broadcast_arrays(np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64))
    if ya.ndim == 0:
        return np.float64(math.atan2(float(ya), float(xa)))
    out = np.fromiter(map(math.atan2, ya.ravel().tolist(), xa.ravel().tolist()), np.float64, count=ya.size)
    return out.reshape(ya.shape)
