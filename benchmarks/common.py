"""Shared helpers for benchmark and accuracy scripts: timing and one table format."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass
class Row:
    """One measured stage: `scans` processed in `seconds` (wall time, one core)."""

    stage: str
    scans: int
    seconds: float
    note: str = ""

    @property
    def scans_per_s(self) -> float:
        return self.scans / self.seconds if self.seconds > 0 else float("inf")

    @property
    def us_per_scan(self) -> float:
        return 1e6 * self.seconds / self.scans if self.scans else float("nan")


def best_of(fn: Callable[[], object], repeat: int = 3) -> float:
    """The shortest wall time of `repeat` calls of `fn`, in seconds."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def print_table(title: str, rows: list[Row]) -> None:
    """Print rows as a table: stage, scans, scans/s, µs/scan, note."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for col in ("stage", "scans", "scans/s", "µs/scan", "note"):
        table.add_column(col, justify="left" if col in ("stage", "note") else "right")
    for r in rows:
        table.add_row(r.stage, f"{r.scans:,}", f"{r.scans_per_s:,.0f}", f"{r.us_per_scan:,.1f}", r.note)
    Console(width=140).print(table)


def print_lines(title: str, lines: list[str]) -> None:
    """Print a titled block of plain lines (for figures that are not per-scan speeds)."""
    print(f"\n{title}")
    for line in lines:
        print(f"  {line}")
