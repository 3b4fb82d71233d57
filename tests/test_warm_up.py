"""The warm-up's helper process: the perception run as plain Python (so only the tracking compiles there), with
the same features as the compiled kernels give, and the names put back afterwards."""

from __future__ import annotations

import sys

import numpy as np
import pytest

pytestmark = pytest.mark.unit


def _perception_dispatchers() -> int:
    from numba.core.registry import CPUDispatcher

    return sum(
        isinstance(v, CPUDispatcher) and v.py_func.__module__.startswith("datmo_cli.perception")
        for name, m in list(sys.modules.items())
        if m is not None and name.startswith("datmo_cli")
        for v in list(vars(m).values())
    )


def test_the_perception_in_python_gives_the_compiled_features_and_is_put_back():
    from datmo_cli.passes.pipeline import perception_in_python
    from datmo_cli.passes.stages import derive_features
    from datmo_cli.sim.simulate import simulate_scene

    sim = simulate_scene("hall", duration=2.0)
    _, compiled = derive_features(sim.run, odometry=sim.odometry)
    with perception_in_python() as replaced:
        assert replaced > 20 and _perception_dispatchers() == 0
        _, plain = derive_features(sim.run, odometry=sim.odometry)
    assert _perception_dispatchers() == replaced
    for name in ("lines", "circles", "blobs", "legs"):
        a, b = getattr(compiled, name), getattr(plain, name)
        assert a.dtype == b.dtype and len(a) == len(b) > 0, name
        for field in a.dtype.names:
            if np.issubdtype(a.dtype[field], np.floating):
                np.testing.assert_allclose(a[field], b[field], rtol=1e-6, atol=1e-9, err_msg=f"{name}.{field}")
            else:
                assert np.array_equal(a[field], b[field]), f"{name}.{field}"


def test_no_helper_when_the_kernels_are_cached_or_in_the_helper(monkeypatch):
    from datmo_cli.base import numba_runtime
    from datmo_cli.passes import pipeline

    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: False)
    assert pipeline._tracking_helper() is None
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setenv("DATMO_WARM_HELPER", "0")
    assert pipeline._tracking_helper() is None


def test_the_helper_compiles_the_tracking_quietly_when_the_kernels_look_uncompiled(monkeypatch):
    import os
    import subprocess

    from datmo_cli.base import numba_runtime
    from datmo_cli.passes import pipeline

    started = []
    monkeypatch.delenv("DATMO_WARM_HELPER", raising=False)
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(subprocess, "Popen", lambda args, **kw: started.append((args, kw)) or "helper")
    assert pipeline._tracking_helper() == "helper"
    ((args, kw),) = started
    assert "warm_tracking()" in args[-1]
    assert kw["env"]["DATMO_WARM_HELPER"] == "0" and kw["env"]["DATMO_COMPILE_NOTICE"] == "0"
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert pipeline._tracking_helper() is None  # one core: nothing to gain
