"""What the commands say while they work: one progress helper (a bar, or a panel redrawn in place), `--quiet`,
and consoles for piped output. The --quiet option itself is Click's: datmo_cli/commands/types.py.

Rules shared by every command:
- progress goes to stderr, as a rich bar with a known total (`bar`) or a panel of counts (`Panel`) on a
  terminal; when stderr is not a terminal (a pipe, a file, CI) nothing is drawn (no control codes, no
  redraws), and under --quiet nothing at all;
- informational lines (`say`) go to stderr unless --quiet; warnings and errors always do;
- tables on stdout never wrap or cut names when stdout is not a terminal (`console`), so
  `datmo info out.mcap | grep MarkerArray` sees whole type names.

rich is imported only when a bar, a panel or a console is made, so `datmo --help` stays light.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import IO, Any, cast

QUIET_KEY = "datmo.quiet"  # in the running command's meta (command_meta), shared by a command and its group
PIPE_WIDTH = 10_000  # columns of a console that is not a terminal: wide enough never to wrap a row


def _no_command() -> dict[str, Any] | None:
    return None


_command_meta: Callable[[], dict[str, Any] | None] = _no_command


def use_command_meta(source: Callable[[], dict[str, Any] | None]) -> None:
    """Set where `command_meta` finds the running command's state: the CLI layer gives Click's context meta
    (datmo_cli/commands/types.py), so this module needs no click."""
    global _command_meta
    _command_meta = source


def command_meta() -> dict[str, Any] | None:
    """The running command's state, shared by a command and its group (e.g. QUIET_KEY), or None outside a
    command (a library call, another thread, a worker process)."""
    return _command_meta()


def quiet() -> bool:
    """Whether the running command was given --quiet (False outside a command, e.g. in a worker process)."""
    meta = command_meta()
    return bool(meta is not None and meta.get(QUIET_KEY))


def stderr_line(line: str) -> None:
    """`line` on stderr, always (a warning, said even under --quiet)."""
    import sys

    sys.stderr.write(f"{line}\n")
    sys.stderr.flush()


def say(message: str) -> None:
    """An informational line on stderr, unless --quiet (control characters escaped: text.printable)."""
    from .text import printable

    if not quiet():
        stderr_line(printable(message))


def console(*, stderr: bool = False):
    """A rich console on stdout (or stderr) for tables: the terminal's width on a terminal; otherwise
    PIPE_WIDTH columns, no wrapping and no colour, so piped and redirected output keeps every name whole.
    Emoji codes are not replaced (`:smile:` in a log's header or metadata prints as written)."""
    import sys

    from rich.console import Console

    stream = sys.stderr if stderr else sys.stdout
    if _isatty(stream):
        return Console(stderr=stderr, emoji=False)
    plain = Console(
        file=cast(IO[str], _Trimmed(stream)),
        width=PIPE_WIDTH,
        soft_wrap=True,
        no_color=True,
        highlight=False,
        emoji=False,
    )
    plain.datmo_plain = True  # type: ignore[attr-defined]  # a mark the table reads
    return plain


def table(console, **kwargs):
    """A rich Table for `console`: boxed on a terminal; plain columns without borders on a console that is
    not one (see `console`), whose trimmed lines then end with their own text, not padded out to the table's
    widest row. Its title and the text of its cells are shown as they are: never read as Rich markup, control
    characters escaped (text.printable), since they often come from a log (topics, frames, metadata)."""
    from rich.text import Text

    from .text import printable

    if getattr(console, "datmo_plain", False):
        kwargs.update(box=None, pad_edge=False)
    if isinstance(kwargs.get("title"), str):
        kwargs["title"] = Text(printable(kwargs["title"]))
    return _plain_table()(**kwargs)


_PLAIN_TABLE: list[type] = []


def _plain_table() -> type:
    """rich's Table whose add_row takes str cells as plain text (rich is imported on first use only)."""
    if not _PLAIN_TABLE:
        from rich.table import Table
        from rich.text import Text

        from .text import printable

        class PlainTable(Table):
            def add_row(self, *cells, **kwargs) -> None:
                super().add_row(*(Text(printable(c)) if isinstance(c, str) else c for c in cells), **kwargs)

        _PLAIN_TABLE.append(PlainTable)
    return _PLAIN_TABLE[0]


class _Trimmed:
    """A text stream that writes whole lines without their trailing spaces."""

    def __init__(self, stream) -> None:
        self.stream = stream
        self.pending = ""

    def write(self, text: str) -> int:
        *lines, self.pending = (self.pending + text).split("\n")
        if lines:
            self.stream.write("".join(line.rstrip() + "\n" for line in lines))
        return len(text)

    def flush(self) -> None:
        if self.pending:
            self.stream.write(self.pending.rstrip())
            self.pending = ""
        self.stream.flush()

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        return self.stream.fileno()


def is_terminal(stream) -> bool:
    """Whether `stream` is a terminal (text written there must not hold control sequences: text.printable)."""
    return _isatty(stream)


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError, OSError):
        return False


def _drawn() -> bool:
    """Whether progress is drawn: stderr is a terminal and the command was not given --quiet."""
    import sys

    return not quiet() and _isatty(sys.stderr)


def _progress_console():
    """The rich console progress is drawn on: the terminal's stderr."""
    from rich.console import Console

    return Console(stderr=True, emoji=False)


class Panel:
    """A rich renderable (e.g. a table of a recording's counts) redrawn in place on stderr, a few times a second,
    removed by `stop()`; nothing under --quiet or when stderr is not a terminal, as for `bar` (decided when
    the Panel is made, in the command). `show(renderable)` starts it, then replaces what it shows; it may be
    called from another thread (a recording loop's progress callback)."""

    def __init__(self, refresh_per_second: float = 4) -> None:
        self.shown = _drawn()
        self.refresh_per_second = refresh_per_second
        self.live: Any = None  # a rich Live once shown

    def show(self, renderable) -> None:
        if not self.shown:
            return
        if self.live is None:
            from rich.live import Live

            self.live = Live(
                renderable, console=_progress_console(), refresh_per_second=self.refresh_per_second, transient=True
            )
            self.live.start()
        else:
            self.live.update(renderable)

    def stop(self) -> None:
        """Remove the panel (nothing if it never started; a terminal that hung up, SIGHUP, is no error)."""
        if self.live is not None:
            try:
                self.live.stop()
            except OSError:
                pass


class Bar:
    """One task of a rich Progress on stderr, or nothing (quiet, not a terminal). `update(done, total)`
    is also the (done, total) callback the pipeline functions take."""

    def __init__(self, progress, task) -> None:
        self.progress = progress
        self.task = task

    @property
    def shown(self) -> bool:
        """Whether a bar is drawn (a terminal, not --quiet)."""
        return self.progress is not None

    def update(self, done: int, total: int | None = None, **fields) -> None:
        """Set the count done (and the total when it becomes known, and any extra column's fields)."""
        if self.progress is not None:
            from .text import markup

            extra = {} if total is None else {"total": total}
            for key in ("description", "info"):  # shown as Rich markup by their columns: a file name, a stage
                if isinstance(fields.get(key), str):
                    fields[key] = markup(fields[key])
            self.progress.update(self.task, completed=done, **extra, **fields)

    def advance(self, n: int = 1, **fields) -> None:
        """Count `n` more done."""
        if self.progress is not None:
            from .text import markup

            for key in ("description", "info"):
                if isinstance(fields.get(key), str):
                    fields[key] = markup(fields[key])
            self.progress.update(self.task, advance=n, **fields)

    def __call__(self, done: int, total: int | None = None) -> None:
        self.update(done, total)

    def tell(self, line: str) -> None:
        """A line said while the bar runs (e.g. a worker's warning): printed above the bar when one is drawn
        (a plain print would tear the bar's line), else on stderr as `say` does, warnings even under --quiet."""
        from .text import printable

        if self.progress is not None:
            self.progress.console.print(printable(line), markup=False, highlight=False, soft_wrap=True)
        elif line.startswith("datmo: warning"):
            stderr_line(printable(line))
        else:
            say(line)

    @contextmanager
    def compile_notice(self) -> Iterator[Callable[[int, int], None]]:
        """A (done, total) callback that also says when numba is compiling the kernels (numba_runtime)."""
        if self.progress is None:
            yield self.update
            return
        from .numba_runtime import compile_notice

        with compile_notice(self.progress, self.task) as report:
            yield report


@contextmanager
def bar(description: str, total: int | None, *, unit: str = "scans", info: bool = False) -> Iterator[Bar]:
    """A progress bar on stderr: `description`, the bar, done/total `unit`, elapsed and remaining time (and,
    with `info`, a free text column set by `update(..., info=TEXT)`). Removed when the block ends.
    Nothing is drawn under --quiet or when stderr is not a terminal."""
    if not _drawn():
        yield Bar(None, None)
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from .text import markup

    columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn(unit)]
    if info:
        columns.append(TextColumn("{task.fields[info]}", style="progress.data.speed"))
    columns += [TimeElapsedColumn(), TimeRemainingColumn()]
    with Progress(*columns, console=_progress_console(), transient=True) as progress:
        extra: dict[str, Any] = {"info": ""} if info else {}
        task = progress.add_task(markup(description), total=total, **extra)
        yield Bar(progress, task)


class Limited:
    """Lines of one kind (a client's bad frames, a publisher's bad messages, a library's log) said on stderr
    through `sink` (default: stderr_line): each one printable line (text.printable; with `multiline`, a
    library's own message of several lines keeps its lines, each escaped, the following ones indented:
    text.printable_lines), the first `burst` of each kind, then at
    most one every `every_s` seconds with the count held back since; `close()` says how many were never
    shown. Thread-safe (the live view's server logs from its own threads)."""

    def __init__(self, prefix: str, burst: int = 5, every_s: float = 60.0, sink=None, multiline: bool = False) -> None:
        import threading

        self.prefix, self.burst, self.every_s, self.multiline = prefix, burst, every_s, multiline
        self.sink = sink or stderr_line
        self.kinds: dict[str, list[float]] = {}  # kind -> [shown, held back, time of the last shown]
        self.lock = threading.Lock()

    def __call__(self, message: object, kind: str = "") -> None:
        import time

        from .text import printable, printable_lines

        now = time.monotonic()
        with self.lock:
            k = self.kinds.setdefault(kind, [0, 0, -1e18])
            if k[0] >= self.burst and now - k[2] < self.every_s:
                k[1] += 1
                if k[1] == 1 and k[0] == self.burst:
                    self.sink(f"{self.prefix}: more such messages are shown at most once a minute")
                return
            lines = printable_lines(message) if self.multiline else [printable(message)]
            if k[1]:
                lines[-1] += f" ({int(k[1]):,} more like it not shown)"
            k[0], k[1], k[2] = k[0] + 1, 0, now
        self.sink("\n".join([f"{self.prefix}: {lines[0]}", *(f"  {line}" for line in lines[1:])]))

    def close(self) -> None:
        held = sum(int(k[1]) for k in self.kinds.values())
        self.kinds.clear()
        if held:
            self.sink(f"{self.prefix}: {held:,} more such messages not shown")


def route_logs(loggers: tuple[str, ...], limited: Limited, level: int = 30) -> Callable[[], None]:
    """Send what the Python loggers `loggers` (another library's: foxglove-sdk's, Dask's) emit at `level` or
    above (default WARNING) to `limited` (escaped, rate-limited, on stderr; a record's traceback is not
    printed) instead of their own handlers or Python's last-resort one. Returns what puts them back."""
    import logging

    class Handler(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            try:
                limited(record.getMessage(), record.name)
            except Exception:
                self.handleError(record)

    handler = Handler(level)
    saved = []
    for name in loggers:
        log = logging.getLogger(name)
        saved.append((log, log.handlers[:], log.propagate))
        log.handlers[:] = [handler]
        log.propagate = False

    def restore() -> None:
        for log, handlers, propagate in saved:
            log.handlers[:] = handlers
            log.propagate = propagate

    return restore
