"""Warming up the numba kernels: `warm_up` compiles every kernel the pipeline runs (or loads it from numba's
cache) before any input's clock starts, once per process. Every caller (`datmo warm-up`, a batch before its
workers start, a Dask worker, the live feed and `datmo node` before the scanner streams) calls it.

The scans it runs the stages on are made here with numpy (`scenes`): a room 12 m x 8 m seen by a 361-beam,
180 deg scanner (0.5 deg, 8 m, 5 Hz) in its sensor frame (x forward, y left; metres, radians, int64 ns): its
walls, three columns and a person's two legs walking across, from a scanner standing still (the hall) and from
one driving forward at 0.5 m/s with its odometry (the patrol). They give lines, circles, blobs, legs, landmarks,
tracks and scan matching, so every kernel the pipeline calls is called with the types a log's scans give
(tests/test_warm_up.py checks the kernels' signatures against the stages' on a simulated log).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ..base import libm

WARM_UP_STEPS = 5  # warm_up's steps: the hall's perception; scan matching; each scene's stages; the simulator
_WARM = False  # this process has warmed up (warm_up)


def warm_up(progress: Callable[[int, int], None] | None = None, *, perception: bool = True) -> None:
    """Compile every numba kernel of the pipeline in this process (or load it from numba's cache), once per
    process (later calls return at once), on the scenes' short runs (`scenes`) and a short run of the
    simulator (its own kernels, for `datmo simulate`), before any input's clock starts and before worker
    processes start: they then inherit the compiled kernels (fork) or find the cache complete (spawn), and never
    compile one kernel at once (a first run after an install would otherwise have every worker writing the same
    cache files). When the kernels are to be compiled and there is a second core, a helper process compiles the
    tracking kernels (warm_up with `perception` False: the perception's kernels run as plain Python there, see
    perception_in_python) while this one compiles the perception's first, then loads the helper's from the
    cache (compiling itself any the helper has not finished; the helper is stopped at the end).
    `progress(done, total)` follows its WARM_UP_STEPS steps."""
    global _WARM
    if _WARM:
        return
    from ..base.numba_runtime import prepare
    from .pipeline import derive

    prepare()
    (hall, _), (patrol, odometry) = scenes()
    if not perception:
        with perception_in_python():
            derive(hall, None, markers=True)
            derive(patrol, odometry, markers=True)
        return
    from ..perception.egomotion import odometry_for
    from .stages import derive_features

    helper = _helper()
    done = 0
    if progress:
        progress(done, WARM_UP_STEPS)

    def step() -> None:
        nonlocal done
        done += 1
        if progress:
            progress(done, WARM_UP_STEPS)

    try:
        derive_features(hall)  # the perception first (the helper: the tracking)
        step()
        odometry_for(patrol, None, "on")  # scan matching, for logs without odometry
        step()
        derive(hall, None, markers=True)  # every stage, the markers' kernels too (--markers, the live view)
        step()
        derive(patrol, odometry, markers=True)  # in the world frame
        step()
        from ..sim.simulate import simulate_scene

        simulate_scene("hall", duration=0.4)  # the simulator's own kernels (ray casting, towing)
        step()
    finally:
        if helper is not None:
            helper.kill()  # numba writes a cache file whole (a temporary file renamed): none is left half-written
            helper.wait()
    _WARM = True


SCAN_NS = 200_000_000  # the scenes' scan period (5 Hz)
ROOM = np.array([[-3.0, -4.0, 9.0, -4.0], [9.0, -4.0, 9.0, 4.0], [9.0, 4.0, -3.0, 4.0], [-3.0, 4.0, -3.0, -4.0]])
COLUMNS = np.array([[4.0, -2.0, 0.25], [4.0, 2.0, 0.25], [7.0, 0.0, 0.2]])  # x, y, radius (m)


def scenes(n: int = 40) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
    """((the hall's ScanRun, None), (the patrol's ScanRun, its Odometry)): `n` scans each (see the module)."""
    from ..logs.scan import Odometry, ScanGeometry, ScanRun

    geometry = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, scan_time=SCAN_NS / 1e9)
    stamps = 1_088_985_600_000_000_000 + np.arange(n, dtype=np.int64) * SCAN_NS
    t = np.arange(n) * SCAN_NS / 1e9
    xs = 0.5 * t
    hall = np.stack([_scan(geometry, 0.0, 0.0, _legs(s)) for s in t])
    patrol = np.stack([_scan(geometry, x, 0.0, _legs(s)) for x, s in zip(xs, t, strict=True)])
    odometry = Odometry(stamps.copy(), xs, np.zeros(n), np.zeros(n), "odom", "base_link")
    return (ScanRun(stamps, hall, geometry), None), (ScanRun(stamps.copy(), patrol, geometry), odometry)


def _legs(t: float) -> np.ndarray:
    """The person's legs at `t` s (x, y, radius in m): walking across the room at 1 m/s, 0.2 m apart, swinging."""
    swing = 0.15 * libm.sin(2 * np.pi * t)
    return np.array([[2.4, -3.0 + t + swing, 0.06], [2.6, -3.0 + t - swing, 0.06]])


def _scan(geometry, x: float, y: float, legs: np.ndarray) -> np.ndarray:
    """The ranges (float32, inf: no return) from a scanner at (x, y) facing +x: the nearest of the room's walls,
    the columns and the legs along each beam."""
    a = geometry.angles()
    dx, dy = libm.cos(a)[:, None], libm.sin(a)[:, None]
    px, py = ROOM[:, 0] - x, ROOM[:, 1] - y
    ex, ey = ROOM[:, 2] - ROOM[:, 0], ROOM[:, 3] - ROOM[:, 1]
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        along, at = (px * ey - py * ex) / den, (px * dy - py * dx) / den
    walls = np.where((at >= 0) & (at <= 1) & (along > 0), along, np.inf).min(axis=1)
    circles = np.vstack([COLUMNS, legs])
    cx, cy, r = circles[:, 0] - x, circles[:, 1] - y, circles[:, 2]
    b = dx * cx + dy * cy
    disc = b * b - (cx * cx + cy * cy - r * r)
    near = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    best = np.minimum(walls, np.where(near > 0, near, np.inf).min(axis=1))
    return np.where(best <= geometry.range_max, best, np.inf).astype(np.float32)


def _helper():
    """The process that compiles the tracking kernels beside warm_up (a subprocess.Popen running warm_up without
    the perception), when the kernels look uncompiled and this process may use two cores or more; None
    otherwise (and in the helper itself: DATMO_WARM_HELPER=0)."""
    import os
    import subprocess
    import sys

    from ..base.numba_runtime import cache_looks_stale

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores < 2 or os.environ.get("DATMO_WARM_HELPER") == "0" or not cache_looks_stale():
        return None
    env = {**os.environ, "DATMO_COMPILE_NOTICE": "0", "DATMO_WARM_HELPER": "0"}
    code = "from datmo_cli.passes.warm import warm_up; warm_up(perception=False)"
    try:
        return subprocess.Popen(
            [sys.executable, "-c", code],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:
        return None


@contextmanager
def perception_in_python() -> Iterator[int]:
    """In the block, every numba kernel of datmo_cli.perception is its plain Python function, wherever a datmo
    module holds it (numba's compiled code is not used and nothing of the perception compiles); yields how many
    names were replaced. Restored after."""
    import importlib
    import pkgutil
    import sys

    from numba.core.registry import CPUDispatcher

    from .. import perception
    from . import feature_channels, stages  # noqa: F401  (loaded, so their names are replaced too)

    for info in pkgutil.iter_modules(perception.__path__):
        importlib.import_module(f"{perception.__name__}.{info.name}")
    replaced = []
    for name, module in list(sys.modules.items()):
        if module is None or not name.startswith("datmo_cli"):
            continue
        for key, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher) and value.py_func.__module__.startswith("datmo_cli.perception"):
                replaced.append((module, key, value))
                setattr(module, key, value.py_func)
    try:
        yield len(replaced)
    finally:
        for module, key, value in replaced:
            setattr(module, key, value)
