"""Optional dependencies: each extra's package missing makes its command fail with one line naming the extra
(no traceback), and `make install` (the dev extra) installs every extra."""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base import extras
from datmo_cli.base.errors import DatmoError
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, encode_scan

pytestmark = pytest.mark.cli

ROOT = Path(__file__).parent.parent


def one_scan_log(path: Path) -> Path:
    """A log of one scan and one empty Tracks message."""
    g = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0)
    stamp = 1_000_000_000
    with mcapio.LogWriter(path) as w:
        w.write(mcapio.TOPIC_SCAN, types.LASERSCAN, stamp, encode_scan(stamp, np.full(361, 3.0, np.float32), g))
        w.write(
            mcapio.TOPIC_TRACKS, types.TRACKS, stamp, cdr.encode(types.TRACKS, {"stamp_ns": stamp, "frame_id": "laser"})
        )
    return path


# (module made missing, command words ({log}: a one-scan log, {out}: a folder for outputs), the error line)
CASES = [
    (
        "sklearn",
        ["train-legs", "--positive", "{log}", "-o", "{out}/m.npz"],
        "training a leg model needs scikit-learn, which is not installed: pip install 'datmo-cli[train]'",
    ),
    (
        "distributed",
        ["run", "{log}", "-o", "{out}/run", "--scheduler", "tcp://127.0.0.1:1"],
        "--scheduler needs dask[distributed], which is not installed: pip install 'datmo-cli[dask]'",
    ),
    (
        "pyarrow",
        ["export", "{log}", "-o", "{out}/tracks.parquet"],
        "writing Parquet needs pyarrow, which is not installed: pip install 'datmo-cli[parquet]'",
    ),
    (
        "foxglove",
        ["play", "{log}", "--port", "0"],
        "the live view needs foxglove-sdk, which is not installed: pip install 'datmo-cli[live]'",
    ),
    (
        "matplotlib",
        ["report", "{log}", "--plot", "{out}/p.png"],
        "--plot needs matplotlib, which is not installed: pip install 'datmo-cli[plot]'",
    ),
    (
        "matplotlib",
        ["run", "{log}", "-o", "{out}/run", "--plot"],
        "--plot needs matplotlib, which is not installed: pip install 'datmo-cli[plot]'",
    ),
    (
        "motmetrics",
        ["evaluate", "{log}"],
        "scoring tracks (datmo evaluate) needs motmetrics, which is not installed: pip install 'datmo-cli[eval]'",
    ),
    (
        "trackeval",
        ["evaluate", "{log}"],
        "scoring tracks (datmo evaluate) needs trackeval, which is not installed: pip install 'datmo-cli[eval]'",
    ),
    (
        "scipy",
        ["evaluate", "{log}"],
        "scoring tracks (datmo evaluate) needs scipy, which is not installed: pip install 'datmo-cli[eval]'",
    ),
    (
        "cyclonedds",
        ["node", "--no-config"],
        "datmo node needs cyclonedds, which is not installed: pip install 'datmo-cli[node]'",
    ),
]


@pytest.mark.parametrize(("module", "args", "line"), CASES, ids=[f"{c[0]}-{c[1][0]}" for c in CASES])
def test_a_missing_extra_is_one_line_naming_it(tmp_path: Path, monkeypatch, module: str, args: list[str], line: str):
    log = one_scan_log(tmp_path / "one.mcap")
    for name in [m for m in sys.modules if m == module or m.startswith(module + ".")] or [module]:
        monkeypatch.setitem(sys.modules, name, None)  # `import name` now raises ImportError
    result = CliRunner().invoke(cli, [a.format(log=log, out=tmp_path) for a in args])
    assert result.exit_code == 1, result.output
    assert result.output.splitlines() == [f"datmo: error: {line}"]
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == [log]  # nothing written


def test_require_gives_the_module_when_it_is_there():
    assert extras.require("pyarrow.parquet", for_="x").__name__ == "pyarrow.parquet"


def test_require_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "fsspec", None)
    with pytest.raises(
        DatmoError, match=re.escape("reading a URL needs fsspec, which is not installed: pip install 'datmo-cli[dask]'")
    ):
        extras.require("fsspec", for_="reading a URL")


def _names(requirements: list[str]) -> set[str]:
    return {re.split(r"[<>=!~ ]", r, maxsplit=1)[0] for r in requirements}


def test_every_extra_is_in_pyproject_and_the_dev_extra_installs_them_all():
    optional = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    for module, (package, extra) in extras.EXTRAS.items():
        assert package in _names(optional[extra]), module
    for extra, requirements in optional.items():
        assert _names(requirements) <= _names(optional["dev"]), extra
        if extra not in ("dev", "all"):
            assert _names(requirements) <= _names(optional["all"]), extra
    assert set(optional) - {"dev", "all"} == {extra for _, extra in extras.EXTRAS.values()}
