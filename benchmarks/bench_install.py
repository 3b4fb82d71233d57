"""The size of a plain install: a fresh venv in a temporary folder, `pip install` of this
clone's package without extras (the wheel pip builds from a copy of the sources), measured on disk; beside it
the dev venv this runs in. Also checked there, as a user would find it: the heavy packages that must stay
extras are not installed, the wheel holds no sample log (csail-excerpt.mcap is GPL-3.0 data), and
`datmo run` and `datmo report` work in that venv on sample_logs/hall.mcap.

Needs the package registries pip is set up with (the dependencies are downloaded or taken from pip's cache);
a few minutes the first time.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from .common import print_lines

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "MANIFEST.in", "datmo_cli")
# distributions a plain install must not pull (normalised names; "opencv" stands for every opencv-* wheel)
HEAVY = (
    "opencv",
    "pandas",
    "matplotlib",
    "trackeval",
    "motmetrics",
    "scikit-learn",
    "scipy",
    "filterpy",
    "pycocotools",
)


def normalise(name: str) -> str:
    """A distribution name as the package index compares them (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def heavy(names: list[str]) -> list[str]:
    """The names among `names` that are (or, for opencv, start like) one of HEAVY."""
    return sorted(n for n in map(normalise, names) if any(n == h or n.startswith(h + "-") for h in HEAVY))


def disk_mb(folder: Path) -> float:
    """Space taken on disk by the files under `folder` (allocated blocks, links not followed), MB."""
    total = 0
    for dirpath, _, files in os.walk(folder):
        for f in files:
            st = os.lstat(os.path.join(dirpath, f))
            total += st.st_blocks * 512
    return total / 1e6


def run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kwargs)


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="datmo-install-") as tmp:
        d = Path(tmp)
        src = d / "src"
        src.mkdir()
        for name in SOURCES:
            path = ROOT / name
            if path.is_dir():
                shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
            elif path.exists():
                shutil.copy2(path, src / name)
        t0 = time.perf_counter()
        run([sys.executable, "-m", "venv", str(d / "venv")])
        pip = [str(d / "venv" / "bin" / "python"), "-m", "pip", "--disable-pip-version-check"]
        run([*pip, "wheel", "--quiet", "--no-deps", "-w", str(d / "wheel"), str(src)])
        wheel = next((d / "wheel").glob("*.whl"))
        run([*pip, "install", "--quiet", str(wheel)])
        seconds = time.perf_counter() - t0
        listed = json.loads(run([*pip, "list", "--format", "json"]).stdout)
        names = [p["name"] for p in listed]
        size = disk_mb(d / "venv")  # as installed (the runs below add numba's cache and .pyc files)
        site = next((d / "venv" / "lib").glob("python*/site-packages"))
        site_size, llvm = disk_mb(site), disk_mb(site / "llvmlite")
        with zipfile.ZipFile(wheel) as z:
            members = z.namelist()
        logs = [m for m in members if m.endswith(".mcap")]
        licence = any(m.endswith("licenses/LICENSE") for m in members)
        datmo = str(d / "venv" / "bin" / "datmo")
        out = d / "out"
        ok, failure = True, []
        try:
            run([datmo, "run", str(ROOT / "sample_logs" / "hall.mcap"), "-o", str(out), "-q", "--no-report"], cwd=d)
            run([datmo, "report", str(out / "hall.mcap"), "--format", "csv"], cwd=d)
        except subprocess.CalledProcessError as exc:
            ok = False
            failure = (exc.stderr or exc.stdout or "").strip().splitlines()[-1:]
        lines = [
            f"plain install (pip install datmo-cli, no extras): venv {size:,.0f} MB on disk, site-packages "
            f"{site_size:,.0f} MB (numba's llvmlite {llvm:,.0f} MB of it), {len(names)} distributions, built and "
            f"installed in {seconds:.0f} s",
            f"dev venv (make install, every extra and the test tools), for comparison: "
            f"{disk_mb(Path(sys.prefix)):,.0f} MB",
            f"heavy packages in the plain install ({', '.join(HEAVY)}): {', '.join(heavy(names)) or 'none'} "
            "(target: none)",
            f"wheel: {len(members)} files, LICENSE {'included' if licence else 'MISSING'}, sample logs: "
            f"{', '.join(logs) or 'none'} (target: none)",
            "datmo run and datmo report on sample_logs/hall.mcap in that venv: "
            + ("ok" if ok else f"FAILED: {' '.join(failure)}"),
        ]
        print_lines("Plain install", lines)


if __name__ == "__main__":
    main()
