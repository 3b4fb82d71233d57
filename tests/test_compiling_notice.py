"""The notice that numba is compiling: shown only while a stage's first progress report is late."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest

from datmo_cli.numba_runtime import NOTICE, compile_notice

pytestmark = pytest.mark.unit


class FakeBar:
    """What compile_notice uses of rich's Progress: update() and tasks."""

    def __init__(self, description: str) -> None:
        self.task = SimpleNamespace(id=0, description=description)
        self.tasks = [self.task]
        self.descriptions: list[str] = []
        self.completed: list[int] = []

    def update(self, task, description=None, completed=None, total=None) -> None:
        if description is not None:
            self.task.description = description
            self.descriptions.append(description)
        if completed is not None:
            self.completed.append(completed)


def test_a_late_first_report_says_the_kernels_compile_then_the_label_returns():
    bar = FakeBar("features")
    with compile_notice(bar, 0, delay=0.05) as report:
        time.sleep(0.3)
        report(256, 300)
        report(300, 300)
    assert bar.descriptions == [f"features: {NOTICE}", "features"]
    assert bar.completed == [256, 300]


def test_a_prompt_first_report_says_nothing():
    bar = FakeBar("features")
    with compile_notice(bar, 0, delay=0.2) as report:
        report(1, 2)
    time.sleep(0.4)
    assert bar.descriptions == []


def test_each_stage_started_with_zero_done_is_watched():
    bar = FakeBar("reading")
    with compile_notice(bar, 0, delay=0.05, armed=False) as report:
        time.sleep(0.15)  # not armed: reading the input says nothing
        bar.update(0, description="features")
        report(0, 10)
        report(10, 10)  # prompt: nothing
        bar.update(0, description="tracking")
        report(0, 10)
        time.sleep(0.3)  # late: compiling
        report(1, 10)
    assert bar.descriptions == ["features", "tracking", f"tracking: {NOTICE}", "tracking"]


def test_a_slow_block_is_said_once_on_stderr(capsys):
    from datmo_cli.numba_runtime import said_if_slow

    with said_if_slow(delay=0.05):
        time.sleep(0.3)
    with said_if_slow(delay=0.5):
        pass
    time.sleep(0.6)
    assert capsys.readouterr().err == f"{NOTICE}...\n"
