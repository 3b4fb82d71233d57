"""Shared fixtures: paths to the shipped sample logs and to ../shared/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# CI reruns the same examples every time (a red build is reproducible); elsewhere hypothesis explores anew.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI", "").lower() == "true":
    settings.load_profile("ci")

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_LOGS = ROOT / "sample_logs"
SHARED_DATA = ROOT.parent / "shared" / "data"


def shared_path(*parts: str) -> Path:
    """A path under ../shared/data; skip the test where it is absent, fail where CI=true."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        reason = f"{path} is absent (../shared/data exists only beside CI's clone)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    return path


@pytest.fixture
def shared_data() -> Path:
    """The ../shared/data folder (skips where absent, fails under CI=true)."""
    return shared_path()


@pytest.fixture(scope="session")
def sample_logs() -> Path:
    return SAMPLE_LOGS


def pytest_terminal_summary(terminalreporter) -> None:
    """Print the fault-injection and fuzz counts (tests/fuzzing.py) after the run."""
    from fuzzing import summary_lines

    lines = summary_lines()
    if lines:
        terminalreporter.section("fault injection and fuzz")
        for line in lines:
            terminalreporter.write_line(line)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark `kernels` the tests tests/kernel_checks.py names as a kernel's reference check."""
    from kernel_checks import CHECKS

    checks = {tuple(node.split("::")) for node in CHECKS.values()}
    for item in items:
        if (item.path.name, getattr(item, "originalname", item.name)) in checks:
            item.add_marker(pytest.mark.kernels)
