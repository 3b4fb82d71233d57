"""The distribution: its name, licence and one version; a plain install that pulls
none of the heavy packages, and `datmo run` and `datmo report` working with only what it installs.

The plain install's requirement closure is read from pyproject.toml's dependencies and, from there on, from the
metadata of the distributions installed here (importlib.metadata; the dev venv holds a superset of the
closure), so it needs no network. `benchmarks/bench_install.py` (make bench) does the real thing: a fresh venv,
`pip install` of the wheel, its size."""

from __future__ import annotations

import importlib.metadata
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner
from packaging.requirements import Requirement

import datmo_cli
from benchmarks.bench_install import heavy, normalise
from datmo_cli.base import extras
from datmo_cli.cli import cli

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
PROJECT = PYPROJECT["project"]
# what the heavy distributions are imported as
HEAVY_MODULES = (
    "cv2",
    "pandas",
    "matplotlib",
    "trackeval",
    "motmetrics",
    "sklearn",
    "scipy",
    "filterpy",
    "pycocotools",
)


def closure(requirements: list[str]) -> dict[str, importlib.metadata.Distribution]:
    """Every distribution `requirements` pull (with their extras), by normalised name, followed through the
    metadata of the installed distributions. Fails on a requirement that is not installed here."""
    found: dict[str, importlib.metadata.Distribution] = {}
    done: set[tuple[str, frozenset[str]]] = set()
    stack = [Requirement(r) for r in requirements]
    while stack:
        req = stack.pop()
        name, wanted = normalise(req.name), frozenset(req.extras)
        if (name, wanted) in done:
            continue
        done.add((name, wanted))
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            pytest.fail(f"{req.name} (pulled by a plain install) is not installed here: run make install")
        found[name] = dist
        for text in dist.requires or []:
            sub = Requirement(text)
            if sub.marker is None or any(sub.marker.evaluate({"extra": e}) for e in ("", *wanted)):
                stack.append(sub)
    return found


def test_the_distribution_is_datmo_cli():
    assert PROJECT["name"] == extras.DISTRIBUTION == "datmo-cli"
    assert PROJECT["scripts"] == {"datmo": "datmo_cli.cli:main"}
    assert (
        importlib.metadata.distribution("datmo-cli").entry_points.select(group="console_scripts")["datmo"].value
        == "datmo_cli.cli:main"
    )


def test_the_version_is_written_once():
    assert "version" not in PROJECT and "version" in PROJECT["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "datmo_cli.__version__"}
    assert importlib.metadata.version("datmo-cli") == datmo_cli.__version__  # after make install
    assert CliRunner().invoke(cli, ["--version"]).output == f"datmo, version {datmo_cli.__version__}\n"
    package_xml = (ROOT / "datmo_msgs" / "package.xml").read_text(encoding="utf-8")  # the ROS 2 package's own
    assert re.search(r"<version>(.*?)</version>", package_xml).group(1) == datmo_cli.__version__


def test_licence_and_metadata():
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License\n")
    assert PROJECT["license"] == "MIT" and PROJECT["license-files"] == ["LICENSE"]
    assert "<license>MIT</license>" in (ROOT / "datmo_msgs" / "package.xml").read_text(encoding="utf-8")
    classifiers = PROJECT["classifiers"]
    assert "Typing :: Typed" in classifiers and (ROOT / "datmo_cli" / "py.typed").exists()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["datmo_cli"]  # in the wheel (PEP 561)
    assert f"Programming Language :: Python :: {PROJECT['requires-python'].removeprefix('>=')}" in classifiers


def test_every_sample_log_has_its_licence_and_none_is_packaged():
    text = (ROOT / "sample_logs" / "README.md").read_text(encoding="utf-8")
    section = text.split("## Licences\n", 1)[1].split("\n## ", 1)[0]
    licences = dict(re.findall(r"^\| `([^`]+\.mcap)` \| (.+?) \|$", section, re.M))
    assert set(licences) == {p.name for p in (ROOT / "sample_logs").glob("*.mcap")}
    assert licences["csail-excerpt.mcap"].startswith("**GPL-3.0**")
    assert all(v.startswith("MIT") for k, v in licences.items() if k != "csail-excerpt.mcap")
    assert PYPROJECT["tool"]["setuptools"]["packages"]["find"]["include"] == ["datmo_cli*"]  # the wheel
    assert "prune sample_logs" in (ROOT / "MANIFEST.in").read_text(encoding="utf-8").splitlines()  # the sdist


def install_lines() -> list[tuple[str, str, str]]:
    """(file, distribution, extras) of every `pip install 'NAME[EXTRAS]'` in the README, the docs, the code's
    help and messages and the benchmarks."""
    files = [
        ROOT / "README.md",
        *sorted((ROOT / "docs").glob("*.md")),
        *sorted((ROOT / "datmo_cli").rglob("*.py")),
        *sorted((ROOT / "benchmarks").glob("*.py")),
    ]
    found = []
    for f in files:
        for name, extra in re.findall(r"pip install '([^'\[]+)\[([^\]]+)\]'", f.read_text(encoding="utf-8")):
            found.append((f.name, name, extra))
    return found


def test_every_install_line_names_datmo_cli_and_an_extra_it_has():
    lines = install_lines()
    assert len(lines) >= 5
    optional = PROJECT["optional-dependencies"]
    for file, name, extra in lines:
        if (name, extra) == ("{DISTRIBUTION}", "{extra}"):  # extras.require's message, filled in from its table
            from datmo_cli.base import extras

            name, extra = extras.DISTRIBUTION, ",".join(sorted({e for _, e in extras.EXTRAS.values()}))
        assert name in ("datmo-cli", "."), (file, name)
        assert all(e in optional for e in extra.split(",")), (file, extra)


def test_a_plain_install_pulls_no_heavy_package():
    plain = closure(PROJECT["dependencies"])
    assert {"numpy", "numba", "llvmlite", "mcap", "rosbags", "rich", "click", "pyserial"} <= set(plain)
    assert heavy(list(plain)) == []
    # the same reading follows extras: the eval extra pulls most of them
    assert {"matplotlib", "motmetrics", "pandas", "pycocotools", "scipy", "trackeval"} <= set(
        heavy(list(closure(["datmo-cli[eval]"])))
    )


def plain_site(folder: Path) -> Path:
    """A folder of links to the top-level entries (packages, modules, shared libraries, dist-info) of every
    distribution a plain install pulls: a site-packages holding that install and nothing else."""
    site = Path(importlib.metadata.distribution("numpy").locate_file(""))
    folder.mkdir()
    for name, dist in closure(PROJECT["dependencies"]).items():
        assert dist.files is not None, name
        for top in {f.parts[0] for f in dist.files if f.parts[0] != ".."}:
            link = folder / top
            if not link.exists() and (site / top).exists():
                link.symlink_to(site / top)
    return folder


# runs in a Python that sees only the plain install's site and this clone (no site-packages, no .pth files)
SCRIPT = r"""
import importlib.util, json, sys
from click.testing import CliRunner
from datmo_cli.cli import cli

heavy = sys.argv[1].split(",")
present = [m for m in heavy if importlib.util.find_spec(m) is not None]
runs = {}
for name, args in [("run", ["run", "hall.mcap", "-o", "out", "--format", "json"]),
                   ("report", ["report", "out/hall.mcap", "--format", "csv"]),
                   ("plot", ["report", "out/hall.mcap", "--plot", "hall.png"]),
                   ("evaluate", ["evaluate", "out/hall.mcap"])]:
    r = CliRunner().invoke(cli, args)
    runs[name] = {"exit": r.exit_code, "stdout": r.stdout, "stderr": r.stderr}
print(json.dumps({"present": present, "loaded": sorted(m for m in heavy if m in sys.modules), "runs": runs}))
"""


def test_run_and_report_work_with_the_plain_install_alone(tmp_path):
    site = plain_site(tmp_path / "site")
    work = tmp_path / "work"
    work.mkdir()
    (work / "hall.mcap").symlink_to(ROOT / "sample_logs" / "hall.mcap")
    boot = f"import sys; sys.path[:0] = [{str(site)!r}, {str(ROOT)!r}]\n"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    proc = subprocess.run(
        [sys.executable, "-I", "-S", "-c", boot + SCRIPT, ",".join(HEAVY_MODULES)],
        cwd=work,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.splitlines()[-1])
    assert got["present"] == [] and got["loaded"] == []  # none of them there, none imported
    runs = got["runs"]
    assert runs["run"]["exit"] == 0, runs["run"]["stderr"]
    assert json.loads(runs["run"]["stdout"])["files"][0]["scans"] == 300
    assert runs["report"]["exit"] == 0 and runs["report"]["stdout"].startswith("file,")
    assert runs["plot"]["exit"] == 1 and runs["plot"]["stderr"] == (
        "datmo: error: --plot needs matplotlib, which is not installed: pip install 'datmo-cli[plot]'\n"
    )
    assert runs["evaluate"]["exit"] == 1 and runs["evaluate"]["stderr"] == (
        "datmo: error: scoring tracks (datmo evaluate) needs scipy, which is not installed: "
        "pip install 'datmo-cli[eval]'\n"
    )
    assert not (work / "hall.png").exists()


def test_an_author_and_no_invented_home():
    assert PROJECT["authors"] == [{"name": "the datmo developers"}]
    assert "Copyright (c) 2026 the datmo developers" in (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert "urls" not in PROJECT  # no public home yet: none is made up


def test_the_sdist_holds_every_file_the_readme_links_to():
    """A package page shows the README alone; its links name the files' paths, and MANIFEST.in puts each of them
    in the source distribution (the sample logs excepted: the README says they are in the repository only).
    (Checked by building the sdist with `python -m build --sdist` too: its files are listed in the report.)"""
    rules = [line.split() for line in (ROOT / "MANIFEST.in").read_text(encoding="utf-8").splitlines()]
    rules = [r for r in rules if r and not r[0].startswith("#")]
    grafted = [r[1] for r in rules if r[0] == "graft"]
    included = {name for r in rules if r[0] == "include" for name in r[1:]} | {"README.md", "LICENSE"}
    pruned = [r[1] for r in rules if r[0] == "prune"]
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = {t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", readme) if "://" not in t}
    targets = {t for t in targets if t and not t.startswith("sample_logs/")}
    assert len(targets) > 10 and "docs/install.md" in targets
    for target in targets:
        assert (ROOT / target).is_file(), target
        assert target in included or any(target.startswith(g + "/") for g in grafted), target
    assert "sample_logs" in pruned and "tests" in pruned


def test_the_package_page_has_no_link_the_index_cannot_follow():
    """The index shows the project's readme alone: docs/package-page.md, with no relative link or image, names
    every command `datmo --help` lists and says where the documentation is."""
    assert PROJECT["readme"] == "docs/package-page.md"
    page = (ROOT / "docs" / "package-page.md").read_text(encoding="utf-8")
    assert not re.search(r"\]\((?![a-z]+://)[^)]*\)", page), "a relative link or image"
    assert not re.search(r"<img|<a ", page)
    from datmo_cli.cli import COMMANDS  # what `datmo --help` lists

    commands = set(COMMANDS)
    assert len(commands) > 15
    missing = {c for c in commands if f"`{c}`" not in page}
    assert not missing, missing


def test_the_python_classifiers_name_only_the_versions_datmo_ran_on():
    """3.11: CI's. 3.13: `make py313` (Debian 13's interpreter, a plain install of the wheel, datmo info and datmo
    run on the hall log). No 3.12 interpreter comes from the registries this project reaches, so none is claimed."""
    versions = {
        c.rsplit(" :: ", 1)[1]
        for c in PROJECT["classifiers"]
        if re.fullmatch(r"Programming Language :: Python :: 3\.\d+", c)
    }
    assert versions == {"3.11", "3.13"}
    recipe = re.search(r"^py313:.*\n\t(.+)$", (ROOT / "Makefile").read_text(), re.M).group(1)
    script = (ROOT / ".ci" / "python313.sh").read_text(encoding="utf-8")
    assert recipe == "bash .ci/python313.sh" and "python3.13 -m venv" in script
    assert re.search(r"datmo run /src/sample_logs/hall\.mcap", script) and "datmo info" in script
