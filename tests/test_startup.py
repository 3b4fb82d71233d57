"""Start-up: what each command imports (in a fresh interpreter), the tables that spare the type store, and
numba's set-up without scipy.linalg. No wall-clock asserts: benchmarks/bench_startup.py measures times."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, encode_scan

pytestmark = pytest.mark.cli

HEAVY = ("numba", "scipy", "scipy.linalg", "sklearn", "rosbags.typesys.stores.ros2_humble", "matplotlib", "dask")

PROBE = """
import json, sys
from datmo_cli.cli import main
try:
    main({args!r})
except SystemExit as exc:
    code = exc.code
else:
    code = 0
print("\\nPROBE " + json.dumps({{"code": code, "heavy": [m for m in {heavy!r} if m in sys.modules]}}))
"""


def imported(args: list[str], cwd: Path) -> tuple[int, list[str]]:
    """(exit code, HEAVY modules in sys.modules) after `datmo ARGS` in a fresh interpreter."""
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(args=args, heavy=HEAVY)],
        capture_output=True,
        text=True,
        cwd=cwd,
        check=True,
    ).stdout
    result = json.loads(out.rsplit("\nPROBE ", 1)[1])
    return result["code"], result["heavy"]


def one_scan_log(path: Path, tracks: bool = False) -> Path:
    """A log of one scan (and, with `tracks`, one empty /datmo/tracks message), written without numba."""
    g = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0)
    stamp = 1_000_000_000
    with mcapio.LogWriter(path) as w:
        w.write(mcapio.TOPIC_SCAN, types.LASERSCAN, stamp, encode_scan(stamp, np.full(361, 3.0, np.float32), g))
        if tracks:
            w.write(
                mcapio.TOPIC_TRACKS,
                types.TRACKS,
                stamp,
                cdr.encode(types.TRACKS, {"stamp_ns": stamp, "frame_id": "laser"}),
            )
    return path


def _light() -> bool:
    from datmo_cli.base.numba_light import light_loading

    return light_loading()


LIGHT = pytest.mark.skipif(
    not _light(), reason="this numba release loads datmo's kernels numba's way (numba_light.NUMBA_RANGE)"
)


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        ["info", "{log}"],
        ["info", "{log}", "--json"],
        ["report", "{done}"],
        ["report", "{done}", "--format", "json"],
        ["export", "{done}", "-o", "-"],
    ],
)
def test_light_commands_import_neither_numba_nor_scipy_nor_the_type_store(tmp_path: Path, args: list[str]):
    log, done = one_scan_log(tmp_path / "one.mcap"), one_scan_log(tmp_path / "done.mcap", tracks=True)
    code, heavy = imported([a.format(log=log, done=done) for a in args], tmp_path)
    assert code == 0
    assert heavy == []


def test_the_command_group_alone_imports_no_numpy(tmp_path: Path):
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; import datmo_cli.cli; print([m for m in ('numpy', 'rich', 'mcap') if m in sys.modules])",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
    ).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("command", ["features", "track", "run"])
def test_stage_commands_load_numba_without_scipy_linalg_or_the_type_store(tmp_path: Path, command: str):
    log = one_scan_log(tmp_path / "one.mcap")
    out = ["-o", str(tmp_path / "out"), "--no-report"] if command == "run" else ["-o", str(tmp_path / "out.mcap")]
    code, heavy = imported([command, str(log), *out], tmp_path)
    assert code == 0
    assert heavy == ["numba", "scipy"]  # scipy's package only (numba's BLAS check), not scipy.linalg


def test_the_field_definitions_read_from_the_msg_files_are_the_type_stores():
    store = types.typestore()
    for msgtype in [*types.datmo_msg_files(), "builtin_interfaces/msg/Time"]:
        assert list(types.fields(msgtype)) == list(store.fielddefs[msgtype][1]), msgtype


def test_the_shipped_schema_table_is_the_type_stores():
    """msg/schemas.json holds what the type store generates (python -m datmo_cli.logs.types rewrites it)."""
    assert types._schema_table() == types.schema_table()
    for msgtype in types.WRITTEN_TYPES:
        assert types.schema_text(msgtype) == types.typestore().generate_msgdef(msgtype, ros_version=2)[0]


def test_numba_is_prepared_without_scipy_linalg_and_scipy_linalg_still_imports_whole(tmp_path: Path):
    """Another package's cached kernel, after prepare: numba's set-up (its BLAS check) runs as it loads or
    compiles, with scipy.linalg.cython_blas loaded on its own, then forgotten."""
    (tmp_path / "theirs.py").write_text("import numba\n\n@numba.njit(cache=True)\ndef g(x):\n    return x + 1\n")
    code = """
import sys
from datmo_cli.base.numba_runtime import prepare
prepare()
import theirs
assert theirs.g(1) == 2
import numba.np.arraymath as arraymath
before = [m for m in sys.modules if m.startswith("scipy.linalg")]
import numpy as np
import numba
import scipy.linalg
from scipy.linalg import cython_blas
f = numba.njit(lambda a, b: np.dot(a, b))
print(before, arraymath._HAVE_BLAS, scipy.linalg.cython_blas is cython_blas, f(np.ones(3), np.ones(3)))
"""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), *sys.path])
    for _ in range(2):  # compiled, then loaded from the cache
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True, env=env
        ).stdout
        assert out.strip() == "[] True True 3.0"


@LIGHT
def test_stage_commands_load_datmos_cached_kernels_without_numbas_registry_refresh(tmp_path: Path):
    """The second run loads every kernel from the cache: numba's registries (here its typed containers and
    random generators, imported only by the refresh) are never set up."""
    log = one_scan_log(tmp_path / "one.mcap")
    probe = PROBE.replace("{heavy!r}", repr(("numba", "numba.typed.typeddict", "numba.np.random.generator_core")))
    for _ in range(2):
        out = subprocess.run(
            [
                sys.executable,
                "-c",
                probe.format(args=["features", str(log), "-o", str(tmp_path / "f.mcap"), "--force"]),
            ],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            check=True,
        ).stdout
    assert json.loads(out.rsplit("\nPROBE ", 1)[1]) == {"code": 0, "heavy": ["numba"]}


@LIGHT
def test_a_kernel_loaded_lightly_still_links_into_a_kernel_compiled_later(tmp_path: Path):
    """A cached datmo kernel's bitcode is left unparsed at load; a kernel compiled later that calls it
    parses it then, to inline it."""
    code = """
import numba
from datmo_cli.base.numba_runtime import prepare
prepare()
from datmo_cli.perception.segmentation import valid_return
loaded = valid_return(1.0, 0.0, 8.0)
library = valid_return.overloads[valid_return.signatures[0]].library
deferred = isinstance(library.__dict__.get("_datmo_shared"), bytes)
g = numba.njit(lambda r: valid_return(r, 0.0, 8.0))
print(loaded, deferred, g(9.0), g(2.0), isinstance(library.__dict__.get("_datmo_shared"), bytes))
"""
    for _ in range(2):  # compiled (if it was not cached), then loaded from the cache
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True)
    assert out.stdout.split() == ["True", "True", "False", "True", "False"]


def test_numba_skips_coverage_unless_a_coverage_run_is_in_progress(tmp_path: Path):
    pytest.importorskip("coverage")
    code = """
import sys
{first}
import datmo_cli
import numba
from numba.misc import coverage_support
import coverage
print("coverage" in sys.modules, coverage_support.coverage_available)
"""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COV_CORE_", "COVERAGE_PROCESS_START"))}
    outs = [
        subprocess.run(
            [sys.executable, "-c", code.format(first=first)], capture_output=True, text=True, cwd=tmp_path, env=env
        ).stdout.split()
        for first in ("", "import coverage")
    ]
    assert outs == [["True", "False"], ["True", "True"]]  # coverage still imports; numba has it only if it came first


def test_the_cache_looks_stale_without_index_files_or_after_an_edit(tmp_path: Path, monkeypatch):
    import os

    from datmo_cli.base import numba_runtime

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    monkeypatch.setattr(numba_runtime, "__file__", str(tmp_path / "numba_runtime.py"))
    source = tmp_path / "perception" / "segmentation.py"
    (source.parent / "__pycache__").mkdir(parents=True)
    source.write_text("")
    assert numba_runtime.cache_looks_stale()  # nothing cached: a first run
    index = source.parent / "__pycache__" / "segmentation.segment_scan-12.py311.nbi"
    index.write_bytes(b"")
    os.utime(source, (1_000, 1_000))
    os.utime(index, (2_000, 2_000))
    assert not numba_runtime.cache_looks_stale()
    os.utime(source, (3_000, 3_000))  # edited after its kernels were cached
    assert numba_runtime.cache_looks_stale()
    monkeypatch.setenv("NUMBA_DISABLE_JIT", "1")
    assert not numba_runtime.cache_looks_stale()
