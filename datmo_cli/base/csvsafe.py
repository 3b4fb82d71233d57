"""Text fields of the CSV files datmo writes, made safe to open in a spreadsheet (CSV or formula injection).

A spreadsheet runs a cell that starts with `=`, `+`, `-` or `@` as a formula (and a leading tab or carriage
return can hide such a start), so a file name or frame id taken from a log could run code or leak data when
someone opens the CSV. `neutralise` prefixes such a text with an apostrophe, which spreadsheets show as text;
a text that is a plain decimal number (`-1.5`, `-2e3`) is left as it is. Only text fields go through it:
numbers datmo writes itself never start with `=`, `+` or `@`.

Used by every CSV writer: `datmo export` (export.py) and `datmo report --format csv` (report.py).
"""

from __future__ import annotations

import re
from collections.abc import Iterable

TRIGGERS = ("=", "+", "-", "@", "\t", "\r")
_NUMBER = re.compile(r"-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def neutralise(text: str) -> str:
    """`text` as a CSV text field is written: with an apostrophe in front when it starts with =, +, @, a tab, a
    carriage return, or - without being a decimal number; else unchanged."""
    if text.startswith(TRIGGERS) and not _NUMBER.fullmatch(text):
        return "'" + text
    return text


def neutralise_row(values: Iterable[object]) -> list[object]:
    """A CSV row's values with every str among them neutralised (numbers and None unchanged)."""
    return [neutralise(v) if isinstance(v, str) else v for v in values]
