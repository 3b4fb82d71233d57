"""The documents in docs/ hold: their examples run as written, in order, in a fresh folder beside a copy of
sample_logs/ (the ```sh blocks' `datmo` lines in-process through Click's runner, then the ```python blocks in one
namespace), docs/export.md's column tables are the export's schema, and every `docs/NAME.md §N` that the package,
the tests and the benchmarks cite names a page and a section that exist."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli import export
from datmo_cli.cli import cli

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def blocks(path: Path) -> list[tuple[str, str]]:
    """(language, text) of every fenced block of `path`, in order."""
    return re.findall(r"^```(\w+)\n(.*?)^```$", path.read_text(encoding="utf-8"), re.S | re.M)


def run_document(path: Path, folder: Path, monkeypatch) -> None:
    """Every sh and python block of `path`, in order, in `folder` (sample_logs/ linked there); a toml block whose
    first line is a comment naming a file (`# space.toml`) is written to that file, as the page asks."""
    (folder / "sample_logs").symlink_to(ROOT / "sample_logs")
    monkeypatch.chdir(folder)
    namespace: dict = {"__name__": f"docs.{path.stem}"}
    for language, text in blocks(path):
        if language == "sh":
            for line in text.splitlines():
                args = shlex.split(line, comments=True)
                if not args:
                    continue
                assert args[0] == "datmo", f"{path.name}: only datmo lines run here: {line}"
                result = CliRunner().invoke(cli, args[1:])
                assert result.exit_code == 0, f"{path.name}: {line}\n{result.output}"
        elif language == "python":
            exec(compile(text, f"{path.name} block", "exec"), namespace)
        elif language == "toml" and (named := re.match(r"# ([\w.-]+\.toml)\n", text)):
            (folder / named.group(1)).write_text(text, encoding="utf-8")


IN_PROCESS = ["export.md", "python.md", "method.md", "lms2xx.md", "tune.md"]  # the pages whose examples run here
SLOW_PAGES = {"tune.md"}  # a tune of 8 trials: under a minute on two cores


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_PAGES else n for n in IN_PROCESS]
)
def test_the_examples_run_as_written(tmp_path, monkeypatch, name):
    run_document(DOCS / name, tmp_path, monkeypatch)


def documented_columns(section: str) -> dict[str, str]:
    """{column: type} of the table under `## section` of docs/export.md (a row may name several columns)."""
    text = (DOCS / "export.md").read_text(encoding="utf-8")
    body = text.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    out = {}
    for names, typ in re.findall(r"^\| ((?:`[^`]+`(?:, )?)+) \| (\w+) \|", body, re.M):
        for name in re.findall(r"`([^`]+)`", names):
            out[name] = typ
    return out


def test_the_documented_columns_are_the_schema():
    assert list(documented_columns("The tracks table").items()) == list(export.TRACK_COLUMNS.items())
    assert list(documented_columns("The feature columns (`--features`)").items()) == list(
        export.FEATURE_COLUMNS.items()
    )
    assert set(export.TRACK_COLUMNS.values()) | set(export.FEATURE_COLUMNS.values()) <= set(export.TYPES)


CITATION = re.compile(r"docs/([\w-]+\.md)((?:(?:,? and |, | )§\d+(?:\.\d+)*)*)")
SECTION = re.compile(r"§(\d+(?:\.\d+)*)")
HEADING_SECTION = re.compile(r"^#+ §(\d+(?:\.\d+)*) ", re.M)


def citations() -> list[tuple[str, str, list[str]]]:
    """(file:line, page, [section numbers]) of every `docs/PAGE.md [§N [and §M]]` in the package, the tests (but
    this file), the benchmarks and the ROS 2 message package."""
    out = []
    files = [
        p
        for folder in ("datmo_cli", "tests", "benchmarks", "datmo_msgs")
        for p in (ROOT / folder).rglob("*")
        if p.suffix in (".py", ".msg") and p.resolve() != Path(__file__).resolve()
    ]
    for path in sorted(files):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for page, sections in CITATION.findall(line):
                out.append((f"{path.relative_to(ROOT)}:{number}", page, SECTION.findall(sections)))
    return out


def test_every_cited_page_and_section_exists():
    cited = citations()
    assert {page for _, page, _ in cited} >= {"method.md", "lms2xx.md"}, "the citations were not found"
    missing = []
    for where, page, sections in cited:
        path = DOCS / page
        if not path.exists():
            missing.append(f"{where}: docs/{page} does not exist")
            continue
        have = set(HEADING_SECTION.findall(path.read_text(encoding="utf-8")))
        missing += [f"{where}: docs/{page} has no section §{n}" for n in sections if n not in have]
    assert not missing, "\n".join(missing)


def test_no_citation_outside_the_repository():
    """The method and the protocol are cited in the repository's docs/, never in a folder beside the clone."""
    stale = [(where, page) for where, page, _ in citations() if page in ("lms2xx-protocol.md",)]
    assert not stale
    for folder in ("datmo_cli", "tests", "benchmarks"):
        for path in (ROOT / folder).rglob("*.py"):
            if path.resolve() == Path(__file__).resolve():
                continue
            text = path.read_text(encoding="utf-8")
            assert "lms2xx-protocol" not in text and "shared/docs" not in text, path
            assert not re.search(r"(?<![\w/])method\.md", text), f"{path}: cite docs/method.md"


# ------------------------------------------------------------------------------------------ every page covered


def test_every_page_runs_somewhere():
    """Every page of docs/ has its examples run: by tests/test_readme.py (the README's guide pages, in order after
    the demo) or here (IN_PROCESS); CONTRIBUTING.md's by test_contributing_commands_run."""
    from test_readme import GUIDE

    guide = {page.name for page in GUIDE if page.parent == DOCS}
    assert not guide & set(IN_PROCESS), "a page runs twice"
    assert {page.name for page in DOCS.glob("*.md")} == guide | set(IN_PROCESS), "a page of docs/ runs nowhere"


def make_targets() -> dict[str, str]:
    """{target: its ## line} of the Makefile."""
    return dict(re.findall(r"^([a-z0-9-]+):.*?## (.+)$", (ROOT / "Makefile").read_text(), re.M))


def test_contributing_commands_run():
    """CONTRIBUTING.md's shell lines: the .venv/bin/ ones run from the clone's top folder and pass; a `make` line
    names a target of the Makefile (not run: make test would run this test again)."""
    import subprocess
    import sys

    lines = [
        line
        for language, text in blocks(ROOT / "CONTRIBUTING.md")
        if language == "sh"
        for line in text.splitlines()
        if line.strip()
    ]
    assert any(line.startswith(".venv/bin/pytest tests/") for line in lines)
    for line in lines:
        args = shlex.split(line, comments=True)
        if args[0] == "make":
            assert args[1] in make_targets(), line
            continue
        assert args[0].startswith(".venv/bin/"), f"CONTRIBUTING.md: only .venv/bin/ and make lines: {line}"
        args[0] = str(Path(sys.executable).with_name(args[0].removeprefix(".venv/bin/")))
        result = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, f"CONTRIBUTING.md: {line}\n{result.stdout[-2000:]}{result.stderr[-2000:]}"


def test_make_help_lists_every_target():
    import subprocess

    result = subprocess.run(["make", "-s", "help"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    phony = re.search(r"^\.PHONY: (.+)$", (ROOT / "Makefile").read_text(), re.M).group(1).split()
    targets = make_targets()
    assert set(phony) <= set(targets), f"targets without a ## line: {set(phony) - set(targets)}"
    for target, line in targets.items():
        assert re.search(rf"^  make {re.escape(target)} +{re.escape(line)}$", result.stdout, re.M), target


# ----------------------------------------------------------------------------------------------- links


LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped but hyphens, spaces made hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.M | re.S)
    return {slug(h) for h in re.findall(r"^#+ (.+)$", text, re.M)}


def test_links_resolve():
    """Every relative link of the README, CONTRIBUTING.md, CHANGELOG.md and docs/ names a file of the repository,
    and a #section of a Markdown page that it has."""
    pages = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", ROOT / "CHANGELOG.md", *sorted(DOCS.glob("*.md"))]
    broken = []
    for page in pages:
        text = re.sub(r"^```.*?^```", "", page.read_text(encoding="utf-8"), flags=re.M | re.S)
        for target in LINK.findall(text):
            if re.match(r"[a-z]+://", target):
                continue
            name, _, anchor = target.partition("#")
            path = (page.parent / name).resolve() if name else page
            if not path.exists():
                broken.append(f"{page.name}: {target} (no such file)")
            elif anchor and path.suffix == ".md" and anchor not in anchors(path):
                broken.append(f"{page.name}: {target} (no such section)")
    assert not broken, "\n".join(broken)


def test_the_readme_is_short_and_shows_the_demo():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200, "the README's long sections belong in docs/"
    assert "](docs/hall.png)" in text and (DOCS / "hall.png").stat().st_size > 10_000
