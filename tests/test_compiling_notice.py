"""The notice that numba is compiling: shown only when a command's first progress report is late."""

from __future__ import annotations

import time

from datmo_cli.commands.compiling import NOTICE, first_report_notice


class FakeBar:
    def __init__(self) -> None:
        self.updates: list[dict] = []

    def update(self, task, **kw) -> None:  # noqa: ANN001
        self.updates.append(kw)


def descriptions(bar: FakeBar) -> list[str]:
    return [u["description"] for u in bar.updates if "description" in u]


def test_a_late_first_report_says_the_kernels_compile_then_the_label_returns():
    bar = FakeBar()
    with first_report_notice(bar, 0, "features", delay=0.05) as report:
        time.sleep(0.3)
        report(256, 300)
        report(300, 300)
    assert descriptions(bar) == [f"features: {NOTICE}", "features"]
    assert {"completed": 300, "total": 300} in bar.updates


def test_a_prompt_first_report_says_nothing():
    bar = FakeBar()
    with first_report_notice(bar, 0, "features", delay=0.2) as report:
        report(1, 2)
    time.sleep(0.4)
    assert descriptions(bar) == ["features"]
