"""The documents in docs/ hold (issue 26 points 5 and 6): their examples run as written, in order, in a fresh
folder beside a copy of sample_logs/ (the ```sh blocks' `datmo` lines in-process through Click's runner, then the
```python blocks in one namespace), and docs/export.md's column tables are the export's schema."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli import export
from datmo_cli.cli import cli

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def blocks(path: Path) -> list[tuple[str, str]]:
    """(language, text) of every fenced block of `path`, in order."""
    return re.findall(r"^```(\w+)\n(.*?)^```$", path.read_text(encoding="utf-8"), re.S | re.M)


def run_document(path: Path, folder: Path, monkeypatch) -> None:
    """Every sh and python block of `path`, in order, in `folder` (sample_logs/ linked there)."""
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


@pytest.mark.parametrize("name", ["export.md", "python.md"])
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
        export.FEATURE_COLUMNS.items())
    assert set(export.TRACK_COLUMNS.values()) | set(export.FEATURE_COLUMNS.values()) <= set(export.TYPES)
