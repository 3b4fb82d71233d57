"""Text that comes from outside datmo (a log's topic, schema and frame names, its metadata, file names,
errors naming them) made safe to show: on a terminal (`printable`) and inside Rich markup (`markup`). (In a
CSV cell a spreadsheet opens: csvsafe.neutralise.)

A log is data anyone can write: its strings must not move the cursor, clear the screen, open a link
(OSC 8), set the window title or break a one-line message, and `[/]` or `[link=...]` in them must not be
read as Rich markup. Nothing here imports rich at module level (base layer, `datmo --help` stays light).
"""

from __future__ import annotations

import re

# C0 controls (tab and newline too: a name is one line), DEL and C1 controls; the line and paragraph
# separators; the bidirectional embeddings, overrides and isolates (they reorder what a terminal shows)
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def _escaped(match: re.Match) -> str:
    c = ord(match.group())
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def printable(text: object) -> str:
    """`text` (str() of it) with every control character, line separator and bidirectional control shown as
    a `\\xNN` or `\\uNNNN` escape: what a terminal shows is what the string holds, on one line. Idempotent."""
    return _UNSAFE.sub(_escaped, str(text))


def markup(text: object) -> str:
    """`text` made printable and escaped for Rich markup: interpolated into a markup string (e.g.
    `f"[bold]{markup(name)}[/]"`) it prints as itself."""
    from rich.markup import escape

    return escape(printable(text))
