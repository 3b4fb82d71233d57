"""numba keys a cached kernel on its own file only; datmo's kernels also compile in constants and kernels of other
files (tracking/state.py's indices, logs/vocabulary.s codes from msg/*.msg, other modules' kernels). Their cache
stamp covers every such file (numba_runtime.KERNEL_SOURCES), so an edit to state.py alone recompiles
tracking/_kernels.py's kernels instead of loading code built on the old indices."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from datmo_cli.base import numba_runtime

pytestmark = pytest.mark.unit


def test_a_datmo_kernels_cache_stamp_covers_the_files_it_reads():
    from datmo_cli.perception import segmentation
    from datmo_cli.tracking import _kernels

    for kernel in (_kernels.pair_legs, segmentation.valid_return):
        own, sources = kernel._cache._impl.locator.get_source_stamp()
        assert sources == numba_runtime.sources_stamp()
        names = {path for path, _, _ in sources}
        assert {
            "tracking/state.py",
            "logs/vocabulary.py",
            "tracking/_kernels.py",
            "perception/segmentation.py",
        } <= names
        assert any(name.startswith("msg/") for name in names)


def test_the_stamp_changes_when_a_file_a_kernel_reads_changes(tmp_path):
    package = Path(numba_runtime.__file__).parent
    copy = tmp_path / "datmo_cli"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = numba_runtime.sources_stamp(str(copy))
    state = copy / "tracking" / "state.py"
    st = state.stat()
    os.utime(state, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    assert numba_runtime.sources_stamp(str(copy)) != before
    (copy / "msg" / "Track.msg").write_text((copy / "msg" / "Track.msg").read_text() + "\n")
    assert numba_runtime.sources_stamp(str(copy)) != numba_runtime.sources_stamp(str(package))


def test_other_packages_kernels_keep_numbas_stamp(tmp_path):
    import importlib.util
    import sys

    source = "from numba import njit\n\n\n@njit(cache=True)\ndef one():\n    return 1\n"
    (tmp_path / "other_kernels.py").write_text(source)
    spec = importlib.util.spec_from_file_location("other_kernels", tmp_path / "other_kernels.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["other_kernels"] = module
    try:
        spec.loader.exec_module(module)
        stamp = module.one._cache._impl.locator.get_source_stamp()
    finally:
        del sys.modules["other_kernels"]
    assert not (isinstance(stamp, tuple) and len(stamp) == 2 and stamp[1] == numba_runtime.sources_stamp())
