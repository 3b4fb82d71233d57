"""Shared fixtures: paths to the shipped sample logs and to ../shared/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# The line "compiling the numba kernels" (numba_runtime.say_compiling) comes once a process when the cache looks
# stale, as it does in a fresh clone while the first tests compile the kernels: not in the tests' outputs
# (their subprocesses inherit this). tests/test_compiling_notice.py turns it on where it checks it.
os.environ["DATMO_COMPILE_NOTICE"] = "0"
os.environ["DATMO_WARM_HELPER"] = "0"  # no second compiling process beside each xdist worker's (warm.warm_up)

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


def pytest_sessionfinish(session: pytest.Session) -> None:
    """On a pytest-xdist worker: hand its fault-injection and fuzz counts to the controller, which prints them."""
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        from fuzzing import COUNTS

        workeroutput["fuzz_counts"] = {name: list(row) for name, row in COUNTS.items()}


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    """On the pytest-xdist controller: add a finished worker's counts to this process's."""
    from fuzzing import COUNTS

    for name, (tried, failures) in getattr(node, "workeroutput", {}).get("fuzz_counts", {}).items():
        COUNTS[name][0] += tried
        COUNTS[name][1] += failures


def pytest_terminal_summary(terminalreporter) -> None:
    """Print the fault-injection and fuzz counts (tests/fuzzing.py) after the run."""
    from fuzzing import summary_lines

    lines = summary_lines()
    if lines:
        terminalreporter.section("fault injection and fuzz")
        for line in lines:
            terminalreporter.write_line(line)


KINDS = ("unit", "cli")  # every test is one: `cli` runs datmo commands (CliRunner, a subprocess), `unit` the rest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark `kernels` the tests tests/kernel_checks.py names as a kernel's reference check, and refuse a test
    marked neither or both of KINDS (a `pytestmark = pytest.mark.unit` or `.cli` per test file)."""
    from kernel_checks import CHECKS

    checks = {tuple(node.split("::")) for node in CHECKS.values()}
    unmarked = []
    for item in items:
        if (item.path.name, getattr(item, "originalname", item.name)) in checks:
            item.add_marker(pytest.mark.kernels)
        if sum(item.get_closest_marker(kind) is not None for kind in KINDS) != 1:
            unmarked.append(item.nodeid)
    if unmarked:
        raise pytest.UsageError(
            "mark each test unit or cli (one of them), e.g. `pytestmark = pytest.mark.unit` in its file:\n  "
            + "\n  ".join(unmarked)
        )
    # the files holding slow tests first (in their order, each whole): a parallel run (make test, --dist loadfile)
    # hands them out before the quick ones, so the workers finish together instead of one waiting on the last slow file
    slow_files = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.path not in slow_files)
