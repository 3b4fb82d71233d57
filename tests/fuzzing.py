"""Counts of the fault-injection and fuzz cases, printed at the end of `make test`.

A fuzz or fault-injection test calls `tally(name)` once per case it tries and `tally(name, failed=True)`
for a case that broke a promise (the test then fails too); `conftest.pytest_terminal_summary` prints the
totals, so a run shows how many cases were tried, not only that the tests passed.
"""

from __future__ import annotations

from collections import defaultdict

COUNTS: dict[str, list[int]] = defaultdict(lambda: [0, 0])  # name -> [cases tried, failures]


def tally(name: str, *, failed: bool = False) -> None:
    """Count one case of the fuzz or fault-injection family `name` (and whether it broke a promise)."""
    row = COUNTS[name]
    row[0] += 1
    row[1] += int(failed)


def summary_lines() -> list[str]:
    """One line per family: cases tried and failures."""
    return [f"{name}: {tried} cases tried, {failures} failures" for name, (tried, failures) in sorted(COUNTS.items())]
