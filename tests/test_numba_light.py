"""numba_light: the patches of numba's internals made for speed, applied only on the numba releases they were
tested against (NUMBA_RANGE, which pyproject.toml and constraints.txt agree with), and never with
DATMO_NUMBA_LIGHT=0; what they change (a plain array's type, the environments of numba's own modules) is what
numba would have given."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from datmo_cli.base import numba_light

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent

# in a fresh process: prepare(), then whether each patch is in place and a cached kernel's result
PROBE = """
import sys
{before}
from datmo_cli.base.numba_runtime import prepare
prepare()
from numba.core import caching, environment
from datmo_cli.tracking import _kernels
patched = [
    getattr(caching.Cache.load_overload, "datmo_light", False),
    getattr(environment._rebuild_env, "datmo_light", False),
]
import numpy as np
print(patched, _kernels._span_max(np.array([1.0, 5.0, 3.0]), 0, 2))
"""


def probe(env: dict[str, str], before: str = "") -> str:
    return subprocess.run(
        [sys.executable, "-c", PROBE.format(before=before)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, **env},
        check=True,
    ).stdout.strip()


def test_pyproject_bounds_numba_to_the_range_the_patches_were_tested_against():
    text = (ROOT / "pyproject.toml").read_text()
    spec = re.search(r'"numba(>=[^"]*)"', text)
    assert spec is not None
    low, high = numba_light.NUMBA_RANGE
    assert spec.group(1) == f">={'.'.join(map(str, low))},<{'.'.join(map(str, high))}"


def test_constraints_pin_a_numba_inside_the_range():
    pinned = re.search(r"^numba==(\S+)$", (ROOT / "constraints.txt").read_text(), re.M)
    assert pinned is not None and numba_light.in_range(pinned.group(1))


@pytest.mark.parametrize(
    ("version", "inside"),
    [("0.68.1", True), ("0.68.7", True), ("0.68.2.dev0", True), ("0.68.0", False), ("0.69.0rc1", False)]
    + [("0.58.1", False), ("1.0.0", False), ("0.68", False), ("garbage", False)],
)
def test_the_range(version: str, inside: bool):
    assert numba_light.in_range(version) is inside


def test_the_patches_are_applied_inside_the_range_and_not_with_the_light_loading_off():
    import numba

    if not numba_light.in_range(numba.__version__):
        pytest.skip("this numba is outside NUMBA_RANGE")
    assert probe({"DATMO_NUMBA_LIGHT": "1"}) == probe({"DATMO_NUMBA_LIGHT": "0"}).replace("False", "True")
    assert probe({"DATMO_NUMBA_LIGHT": "0"}).startswith("[False, False]")


def test_nothing_is_patched_on_a_numba_outside_the_range():
    out = probe({"DATMO_NUMBA_LIGHT": "1"}, before="import numba; numba.__version__ = '0.70.0'")
    assert out.startswith("[False, False]")
    assert out == probe({"DATMO_NUMBA_LIGHT": "0"})


ARRAYS = [
    np.zeros(3),
    np.zeros((2, 3), np.float32, order="F"),
    np.zeros((4, 4), np.int64)[::2, 1:],
    np.zeros(()),
    np.zeros(2, dtype=[("a", np.float64), ("b", np.int32)]),
    np.frombuffer(b"\0" * 16, np.float64),  # read-only
]


@pytest.mark.parametrize("value", ARRAYS, ids=lambda a: f"{a.dtype}-{a.ndim}d-{a.flags.c_contiguous}")
def test_a_plain_arrays_type_is_numbas(value: np.ndarray):
    from numba.core.typing import typeof

    numba_light._plain_arrays_typed_directly()
    ours = typeof.typeof_impl.dispatch(np.ndarray)
    original = getattr(ours, "__wrapped__", None)
    assert getattr(ours, "datmo_light", False) and original is not None
    assert ours(value, None) == original(value, None)


def test_a_masked_array_is_still_refused():
    import numba
    from numba.core import errors

    numba_light._plain_arrays_typed_directly()
    with pytest.raises(errors.NumbaTypeError, match="MaskedArray"):
        numba.typeof(np.ma.masked_array([1.0, 2.0]))


def test_an_environment_of_numbas_own_module_not_imported_yet_is_a_stand_in():
    code = """
import sys
from datmo_cli.base.numba_runtime import prepare
prepare()
from numba.core import environment
env = environment._rebuild_env("numba.np.arrayobj", [1, 2], "datmo-test-env")
again = environment._rebuild_env("numba.np.arrayobj", [1, 2], "datmo-test-env")
print("numba.np.arrayobj" in sys.modules, env.globals, list(env.consts), again is env)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.split("\n")[0] == "False {'__name__': 'numba.np.arrayobj'} [1, 2] True"


def test_stage_commands_load_the_kernels_without_numpy_ma_or_numbas_array_module(tmp_path: Path):
    """The kernels the stages run load without importing numpy.ma (numba's masked-array check) or numba's
    array implementations (the environments' modules): both only for compiling or for object mode."""
    import numba

    if not numba_light.light_loading():
        pytest.skip("light loading off or this numba is outside NUMBA_RANGE")
    log = tmp_path / "one.mcap"
    datmo = [sys.executable, "-c", "from datmo_cli.cli import main; main()"]
    subprocess.run([*datmo, "simulate", "--scene", "hall", "--duration", "0.2", "-o", str(log)], check=True)
    code = (
        "import sys, runpy; sys.argv = ['datmo', 'features', {log!r}, '-o', {out!r}, '--force'];\n"
        "from datmo_cli.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "print('LOADED', [m for m in ('numpy.ma', 'numba.np.arrayobj', 'numba.cpython.unicode') if m in sys.modules])"
    ).format(log=str(log), out=str(tmp_path / "f.mcap"))
    for _ in range(2):  # compiled if the cache is cold, then loaded
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True)
    assert out.stdout.rsplit("LOADED ", 1)[1].strip() == "[]", numba.__version__
