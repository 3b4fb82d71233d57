"""The pre-commit hooks run what `make lint` runs: ruff check and ruff format --check, at the ruff CI pins."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent


def test_precommit_hooks_are_make_lint():
    config = (ROOT / ".pre-commit-config.yaml").read_text()
    lint = re.search(r"^lint:.*\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    assert lint is not None
    assert "ruff check ." in lint.group(1) and "ruff format --check ." in lint.group(1)
    hooks = re.findall(r"- id: (\S+)", config)
    assert hooks == ["ruff", "ruff-format"]
    assert "args: [--check]" in config.split("id: ruff-format", 1)[1]
    assert "files:" not in config  # the whole repository, as `make lint`


def test_precommit_ruff_is_the_pinned_ruff():
    rev = re.search(r"rev: v(\S+)", (ROOT / ".pre-commit-config.yaml").read_text())
    pin = re.search(r"^ruff==(\S+)$", (ROOT / "constraints.txt").read_text(), re.M)
    assert rev and pin and rev.group(1) == pin.group(1)
