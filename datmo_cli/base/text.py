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
# separators; every format character of Unicode (category Cf: the bidirectional marks, embeddings, overrides
# and isolates, which reorder what a terminal shows; the invisible ones: soft hyphen, zero-width space and
# joiners, word joiner, BOM, the tags) and the Hangul fillers, which show as nothing: a name that holds them
# would look like another
UNSAFE = re.compile(
    "[\x00-\x1f\x7f-\x9f\xad\u0600-\u0605\u061c\u06dd\u070f\u0890\u0891\u08e2\u115f\u1160\u180e"
    "\u200b-\u200f\u2028-\u202e\u2060-\u206f\u3164\ufeff\uffa0\ufff9-\ufffb\U000110bd\U000110cd"
    "\U00013430-\U0001343f\U0001bca0-\U0001bca3\U0001d173-\U0001d17a\U000e0001\U000e0020-\U000e007f]"
)


def _escaped(match: re.Match) -> str:
    c = ord(match.group())
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}" if c < 0x10000 else f"\\U{c:08x}"


def printable(text: object) -> str:
    """`text` (str() of it) with every control character, line separator and bidirectional control shown as
    a `\\xNN` or `\\uNNNN` escape: what a terminal shows is what the string holds, on one line. Idempotent."""
    return UNSAFE.sub(_escaped, str(text))


def markup(text: object) -> str:
    """`text` made printable and escaped for Rich markup: interpolated into a markup string (e.g.
    `f"[bold]{markup(name)}[/]"`) it prints as itself."""
    from rich.markup import escape

    return escape(printable(text))


# ASCII punctuation that starts a Markdown or HTML construct: emphasis, links and images, headings, code,
# tables, HTML tags and entities, strikethrough
_MARKDOWN = re.compile(r"([\\`*_\[\]<>#!|~&])")


def markdown(text: object) -> str:
    """`text` made printable and escaped for GitHub-flavoured Markdown: each character that could start a link,
    an image, a heading, emphasis, code, a table cell or an HTML tag or entity gets a backslash, so a page
    (a CI job summary, a rendered report) shows it as the text it is."""
    return _MARKDOWN.sub(r"\\\1", printable(text))


def printable_lines(text: object) -> list[str]:
    """`text` as the printable lines it holds (for a message of another library that spans lines, e.g. a
    Dask warning): split at its line breaks, each line printable, trailing blank lines dropped."""
    lines = [printable(line) for line in re.split(r"\r\n|[\n\r\u2028\u2029\x0b\x0c\x1c-\x1e\x85]", str(text))]
    while lines and not lines[-1].strip():
        lines.pop()
    return lines or [""]
