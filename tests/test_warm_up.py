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
    from datmo_cli.passes.stages import derive_features
    from datmo_cli.passes.warm import perception_in_python
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
    from datmo_cli.passes import warm

    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: False)
    assert warm._helper() is None
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setenv("DATMO_WARM_HELPER", "0")
    assert warm._helper() is None


def test_the_helper_compiles_the_tracking_quietly_when_the_kernels_look_uncompiled(monkeypatch):
    import os
    import subprocess

    from datmo_cli.base import numba_runtime
    from datmo_cli.passes import warm

    started = []
    monkeypatch.delenv("DATMO_WARM_HELPER", raising=False)
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(subprocess, "Popen", lambda args, **kw: started.append((args, kw)) or "helper")
    assert warm._helper() == "helper"
    ((args, kw),) = started
    assert "warm_up(perception=False)" in args[-1]
    assert kw["env"]["DATMO_WARM_HELPER"] == "0" and kw["env"]["DATMO_COMPILE_NOTICE"] == "0"
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert warm._helper() is None  # one core: nothing to gain


ENTRY_SIGNATURES = """
import json, sys
from numba.core.registry import CPUDispatcher
from datmo_cli.base.numba_runtime import prepare

prepare()
if sys.argv[1] == "warm_up":
    from datmo_cli.passes.warm import warm_up

    warm_up()
else:  # the stages on simulated logs, the hall (people, a platform, benches) and the patrol (odometry), as
    # datmo features, datmo run (scan matching for a log without odometry) and the live view call them
    from datmo_cli.perception.egomotion import odometry_for
    from datmo_cli.passes.pipeline import derive
    from datmo_cli.sim.simulate import simulate_scene
    from datmo_cli.passes.stages import derive_features

    for scene in ("hall", "patrol"):
        sim = simulate_scene(scene, duration=8.0)
        derive_features(sim.run, odometry=sim.odometry)
        odometry_for(sim.run, None, "on")
        derive(sim.run, sim.odometry, markers=True)
out = {}
for name, module in list(sys.modules.items()):
    if module is not None and name.startswith("datmo_cli"):
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher) and value.signatures:
                out[value.py_func.__module__ + "." + value.py_func.__qualname__] = sorted(map(str, value.signatures))
print(json.dumps(out))
"""


def _entry_signatures(what: str) -> dict[str, list[str]]:
    """{kernel: its compiled signatures} that a fresh process called from Python after `what`."""
    import json
    import subprocess

    done = subprocess.run(
        [sys.executable, "-c", ENTRY_SIGNATURES, what], capture_output=True, text=True, check=True, timeout=900
    )
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.slow
def test_the_warm_up_compiles_every_kernel_a_run_calls_with_the_same_types():
    """warm_up's scenes are made with numpy, not simulated: the kernels the stages call from Python on simulated
    logs (with and without odometry, scan matching, the markers) are the kernels it calls, with the same types."""
    warmed, run = _entry_signatures("warm_up"), _entry_signatures("run")
    assert len(run) >= 15
    assert {k: v for k, v in run.items() if not k.startswith("datmo_cli.sim.")} == {
        k: v for k, v in warmed.items() if not k.startswith("datmo_cli.sim.")
    }
    assert warmed.keys() >= {k for k in run if k.startswith("datmo_cli.sim.")}  # the simulator's own, too


def test_the_scenes_give_every_kind_of_feature_and_tracks():
    from datmo_cli.passes.pipeline import derive
    from datmo_cli.passes.stages import derive_features
    from datmo_cli.passes.warm import scenes

    (hall, none), (patrol, odometry) = scenes()
    assert none is None and len(odometry) == len(patrol) == len(hall) == 40
    assert hall.ranges.dtype == np.float32 and np.isinf(hall.ranges).any() and np.isfinite(hall.ranges).any()
    _, f = derive_features(hall)
    assert min(len(f.lines), len(f.circles), len(f.blobs), len(f.legs)) > 0
    derived, _ = derive(patrol, odometry, markers=True)
    assert sum(len(p) for p in derived["/datmo/tracks"][2]) > 40 * 100  # tracks in most scans


def test_warm_up_runs_once_a_process(monkeypatch):
    from datmo_cli.base import numba_runtime
    from datmo_cli.passes import warm

    calls = []
    monkeypatch.setattr(warm, "_WARM", False)
    monkeypatch.setattr(warm, "scenes", lambda: calls.append(1) or ((None, None), (None, None)))
    monkeypatch.setattr(warm, "_helper", lambda: None)
    monkeypatch.setattr(numba_runtime, "prepare", lambda: None)
    import datmo_cli.perception.egomotion as ego
    from datmo_cli.passes import pipeline, stages

    steps = []
    monkeypatch.setattr(stages, "derive_features", lambda *a, **k: None)
    monkeypatch.setattr(ego, "odometry_for", lambda *a, **k: None)
    monkeypatch.setattr(pipeline, "derive", lambda *a, **k: None)
    import datmo_cli.sim.simulate as simulate

    monkeypatch.setattr(simulate, "simulate_scene", lambda *a, **k: None)
    warm.warm_up(lambda done, total: steps.append((done, total)))
    warm.warm_up(lambda done, total: steps.append((done, total)))
    assert calls == [1] and steps == [(k, warm.WARM_UP_STEPS) for k in range(warm.WARM_UP_STEPS + 1)]
