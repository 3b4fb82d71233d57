"""A read-only install run by a user without a writable HOME: numba found nowhere to cache a
kernel and every stage exited 70 ("cannot cache function ...: no locator available"). datmo then caches in a
private folder of the temporary folder, or, without one, compiles in each process without a cache.

The install is a copy of the package whose every `__pycache__` is a file (no folder can be made there, as on a
read-only file system, and this holds for root too); HOME lies under a file."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from datmo_cli.base import numba_runtime

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def read_only_install(tmp_path_factory) -> Path:
    site = tmp_path_factory.mktemp("site")
    shutil.copytree(ROOT / "datmo_cli", site / "datmo_cli", ignore=shutil.ignore_patterns("__pycache__"))
    for folder in [site / "datmo_cli", *(p for p in (site / "datmo_cli").rglob("*") if p.is_dir())]:
        (folder / "__pycache__").write_text("")
    return site


def run_python(site: Path, tmp_path: Path, script: str, temp: str) -> subprocess.CompletedProcess:
    """`script` in a fresh interpreter importing datmo from `site`, HOME under a file, the temporary folder
    `temp` (set before datmo is imported)."""
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHONPATH")}
    env.update(PYTHONPATH=str(site), HOME=str(blocked / "home"), PYTHONDONTWRITEBYTECODE="1")
    prelude = f"import tempfile; tempfile.tempdir = {temp!r}\n"
    return subprocess.run(
        [sys.executable, "-c", prelude + script], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300
    )


def test_kernels_cache_in_a_private_temporary_folder(read_only_install, tmp_path):
    temp = tmp_path / "tmp"
    temp.mkdir()
    hall = ROOT / "sample_logs" / "hall.mcap"
    script = (
        "import os, sys\n"
        "from datmo_cli.cli import main\n"
        "try:\n"
        f"    main(['segment', {str(hall)!r}, '-o', 'out.mcap', '-q'])\n"
        "except SystemExit as exc:\n"
        "    assert not exc.code, exc.code\n"
        "import datmo_cli.sim._kernels as k\n"
        "print(os.environ['NUMBA_CACHE_DIR']); print(k.cast_batch._cache._cache_path)\n"
    )
    done = run_python(read_only_install, tmp_path, script, str(temp))
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    folder, kernel = done.stdout.split()
    uid = os.getuid()
    assert folder == str(temp / f"datmo-numba-cache-{uid}") and kernel.startswith(folder)
    st = os.lstat(folder)
    assert st.st_uid == uid and stat.S_IMODE(st.st_mode) == 0o700
    assert any(p.suffix == ".nbi" for p in Path(folder).rglob("*"))  # segmentation's kernels were cached there
    assert (tmp_path / "out.mcap").is_file()


def test_kernels_compile_uncached_without_a_temporary_folder(read_only_install, tmp_path):
    script = (
        "import os\n"
        "import datmo_cli.sim._kernels as k\n"
        "print(os.environ.get('NUMBA_CACHE_DIR'), type(k.cast_batch._cache).__name__)\n"
    )
    done = run_python(read_only_install, tmp_path, script, str(tmp_path / "a-file" / "tmp"))
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["None", "NullCache"]


def test_a_temporary_cache_folder_another_user_could_write_is_not_used(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    shared = tmp_path / f"datmo-numba-cache-{os.getuid()}"
    shared.mkdir(mode=0o777)
    shared.chmod(0o777)
    chosen = numba_runtime._private_temp()
    assert chosen != str(shared) and Path(chosen).parent == tmp_path
    assert stat.S_IMODE(os.lstat(chosen).st_mode) == 0o700
    shared.chmod(0o700)
    assert numba_runtime._private_temp() == str(shared)  # once only this user may write it, it is kept


def test_nothing_changes_where_numba_can_cache(monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert numba_runtime.choose_cache() is None and "NUMBA_CACHE_DIR" not in os.environ
