"""The `datmo` command group.

Each subcommand lives in its own module under `datmo_cli.commands` and is imported only when it is
run, so `datmo --help` stays instant (no numpy, numba or mcap import).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys

import click

from . import __version__

# name -> (module under datmo_cli.commands, one-line help shown by `datmo --help`)
COMMANDS: dict[str, tuple[str, str]] = {
    "import": ("import_", "Convert a CARMEN log, g2o file, ROS 1/2 bag or MCAP to a datmo scan log."),
    "info": ("info", "Show a log's channels, scan geometry, rate and provenance."),
    "simulate": ("simulate", "Simulate an LMS200 in a scene and write a log with ground truth."),
    "record": ("record", "Record a SICK LMS200 over a serial port into a log."),
    "emulate": ("emulate", "Run a virtual LMS200 on a pseudo-terminal."),
    "segment": ("segment", "Split each scan into segments (adaptive threshold)."),
    "features": ("features", "Extract lines, circles, blobs and landmarks (Hough transforms)."),
    "track": ("track", "Track and classify objects (Kalman filter, people detection)."),
    "run": ("run", "Segment, extract features and track in one pass; then report."),
    "report": ("report", "Summarise what a processed run saw."),
    "export": ("export", "Write every track's state per scan (and features) as CSV, NDJSON or Parquet."),
    "play": ("play", "Serve a log to Foxglove live (WebSocket), processing scans as they play."),
    "node": ("node", "Run live as a ROS 2 node over DDS: LaserScans in, tracks out (no ROS needed)."),
    "evaluate": ("evaluate", "Score tracks against ground truth (CLEAR-MOT, IDF1)."),
    "tune": ("tune", "Find the parameters that score best against ground truth (search, successive halving)."),
    "train-legs": ("train_legs", "Train the learned leg detector on labelled scans; print held-out figures."),
    "config": ("config", "Print the effective configuration ([features], [track]) as TOML."),
    "warm-up": ("warm_up", "Compile the numba kernels ahead of the first run (for images and CI)."),
}


_ARGS: list[str] = []


def invocation(command: str) -> str:
    """The command line that started this run, as `datmo ARGS...` (for provenance metadata)."""
    import shlex

    args = _ARGS or [command]
    return "datmo " + " ".join(shlex.quote(a) for a in args)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning on stderr: datmo's own as one printable line (a log's strings in it are escaped, line breaks
    too); another library's (Dask's, whose warnings span lines) line by line, each escaped, the following ones
    indented: never a raw control sequence, never a `\\x0a` in the middle of a sentence."""
    import os

    from .base.text import printable, printable_lines

    ours = os.path.dirname(os.path.abspath(__file__))
    if os.path.abspath(str(filename)).startswith(ours + os.sep):
        click.echo(f"datmo: warning: {printable(message)}", err=True)
        return
    first, *rest = printable_lines(message)
    click.echo("\n".join([f"datmo: warning: {first}", *(f"  {line}" for line in rest)]), err=True)


def _escape(err: UnicodeError) -> tuple[str, int]:
    """Codec error handler: a file name's byte that is not UTF-8 (a surrogate from os.fsdecode) as \\xNN,
    any other unencodable character as \\uNNNN."""
    if not isinstance(err, UnicodeEncodeError):  # registered for writing only
        raise err
    bad = err.object[err.start : err.end]
    return "".join(
        f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF else f"\\u{ord(c):04x}" for c in bad
    ), err.end


def _safe_streams() -> None:
    """Let stdout and stderr print any file name: bytes that are not UTF-8 come out as \\xNN rather than
    raising UnicodeEncodeError."""
    import codecs

    codecs.register_error("datmo-escape", _escape)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="datmo-escape")  # type: ignore[union-attr]  # may be any TextIO
        except (AttributeError, ValueError, OSError):
            pass


def _debug(ctx: click.Context) -> bool:
    import os

    return bool(ctx.params.get("debug")) or os.environ.get("DATMO_DEBUG", "") not in ("", "0")


_DECOMPRESSION = {"ZstdError", "BadGzipFile", "LZMAError", "LZ4FrameError"}  # exception names of the codecs


def _input_named(exc: BaseException) -> str | None:
    """The one input file argument of the command `exc` came out of, if it has exactly one (to name the
    file in errors that do not say which): read from the subcommand's context on the traceback."""
    import os

    tb, sub = exc.__traceback__, None
    while tb is not None and sub is None:
        candidate = tb.tb_frame.f_locals.get("sub_ctx")
        sub = candidate if isinstance(candidate, click.Context) else None
        tb = tb.tb_next
    if sub is None:
        return None
    found = []
    for param in sub.command.params:
        if isinstance(param, click.Argument):
            value = sub.params.get(param.name)
            values = value if isinstance(value, (tuple, list)) else [value]
            found += [v for v in values if v is not None and os.path.exists(v)]
    return os.fsdecode(found[0]) if len(found) == 1 else None


def clean_error(exc: BaseException) -> CleanError | None:
    """The one-line error (and exit code) for `exc`, or None for an exit that needs no message."""
    from .base import outputs
    from .base.errors import DatmoError

    if isinstance(exc, SystemExit):
        return None
    if isinstance(exc, DatmoError):
        return CleanError(str(exc), exc.exit_code)
    if isinstance(exc, KeyboardInterrupt):
        return CleanError("interrupted (Ctrl-C); unfinished outputs removed", 130)
    if isinstance(exc, outputs.Terminated):
        return CleanError(f"{exc}; unfinished outputs removed", exc.exit_code)
    if isinstance(exc, MemoryError):
        return CleanError("out of memory (a parameter or an input asks for more than this machine has)")
    named = _input_named(exc)
    zlib_error = (type(exc).__module__, type(exc).__name__) == ("zlib", "error")
    if type(exc).__name__ in _DECOMPRESSION or zlib_error or "decompress" in str(exc).lower():
        return CleanError(f"{named + ': ' if named else ''}corrupt compressed data ({exc})")
    if isinstance(exc, OSError):
        return CleanError(str(outputs.os_error(exc)))
    if isinstance(exc, RecursionError):
        return CleanError(f"{named + ': ' if named else ''}input too deeply nested ({exc})")
    import traceback

    ours = [f for f in traceback.extract_tb(exc.__traceback__) if "datmo_cli" in f.filename]
    where = f" at datmo_cli{ours[-1].filename.rsplit('datmo_cli', 1)[-1]}:{ours[-1].lineno}" if ours else ""
    about = f" (input {named})" if named else ""
    return CleanError(
        f"internal error{about}: {type(exc).__name__}: {exc}{where} (a bug: rerun with --debug or "
        "DATMO_DEBUG=1 for the traceback)",
        70,
    )


class CleanError(click.ClickException):
    """A DatmoError as Click shows it: one line on stderr, no traceback."""

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code  # type: ignore[misc]  # Click's default is a class attribute

    def show(self, file=None) -> None:
        from .base.text import printable

        click.echo(f"datmo: error: {printable(self.format_message())}", err=True, file=file)


# the commands that run numba kernels: the line that they are about to compile comes before anything else
KERNEL_COMMANDS = ("segment", "features", "track", "run", "play", "node", "warm-up")


def _say_compiling() -> None:
    """Say at once, before a kernel command's own imports, that the kernels will compile when their cache looks
    stale (numba_runtime.say_compiling; not for --help or --quiet, which are read from the arguments here)."""
    words = [a for a in _ARGS if not a.startswith("-")]
    if not words or words[0] not in KERNEL_COMMANDS or {"--help", "-q", "--quiet"} & set(_ARGS):
        return
    from .base.numba_runtime import say_compiling

    say_compiling()


class LazyGroup(click.Group):
    """A group whose commands are imported on first use, and the one place where errors become messages.

    DatmoError, OSError (the disk full, a read-only folder, a name too long), MemoryError, corrupt
    compressed data and any unexpected exception each give one line on stderr and a non-zero exit, never
    a traceback (`datmo --debug` or DATMO_DEBUG=1 shows it). Ctrl-C exits 130, SIGTERM 143, SIGHUP 129.
    On every way out the temporary files of unfinished outputs are removed (outputs.remove_live)."""

    def main(self, args=None, *rest, **kwargs):
        _ARGS[:] = [str(a) for a in (sys.argv[1:] if args is None else args)]
        return super().main(args, *rest, **kwargs)

    def invoke(self, ctx: click.Context):
        import warnings

        from .base import outputs

        _safe_streams()
        _say_compiling()
        try:
            with warnings.catch_warnings(), outputs.handle_signals():
                warnings.simplefilter("always", UserWarning)
                warnings.showwarning = _show_warning
                return super().invoke(ctx)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except BaseException as exc:
            outputs.remove_live()
            exc = outputs.interrupt_in(exc) or exc
            if _debug(ctx) and not isinstance(exc, (KeyboardInterrupt, outputs.Terminated, SystemExit)):
                raise
            clean = clean_error(exc)
            if clean is None:
                raise
            raise clean from None
        finally:
            outputs.remove_live()

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name in COMMANDS if self._available(name)]

    @staticmethod
    def _available(name: str) -> bool:
        module = COMMANDS[name][0]
        return importlib.util.find_spec(f"datmo_cli.commands.{module}") is not None

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS or not self._available(name):
            return None
        module = importlib.import_module(f"datmo_cli.commands.{COMMANDS[name][0]}")
        return _guard_file_outputs(module.command)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


class _FileOutput(click.ParamType):
    """A file output option's type: Click's Path type, but a value ending in '/' is refused (a Path would
    drop the slash and write a file named like the folder)."""

    def __init__(self, inner: click.Path) -> None:
        self.inner = inner
        self.name = inner.name

    def convert(self, value, param, ctx):
        import os

        if ctx is not None and ctx.params.get("bag_dir"):  # a folder (an eager --bag-dir; log/bagdir.py checks it)
            return self.inner.convert(value, param, ctx)
        if isinstance(value, (str, bytes)) and os.fsdecode(value).endswith(("/", os.sep)):
            from .base.errors import OutputError

            option = param.opts[-1] if param is not None and param.opts else "output"
            raise OutputError(f"{os.fsdecode(value)}: {option} ends with '/' (a folder); give a file name")
        if isinstance(value, (str, bytes)) and os.path.isdir(value):
            from .base.errors import OutputError

            raise OutputError(f"{os.fsdecode(value)}: is a directory; give a file name")
        return self.inner.convert(value, param, ctx)

    def get_metavar(self, *args, **kwargs):
        return self.inner.get_metavar(*args, **kwargs)

    def shell_complete(self, ctx, param, incomplete):
        return self.inner.shell_complete(ctx, param, incomplete)


FILE_OUTPUTS = ("output", "plot", "link")  # option names that name one file a command writes


def _guard_file_outputs(command: click.Command) -> click.Command:
    """Outputs get _FileOutput; every other path (an input) is left to its reader, which says in one line
    (exit 1) what is wrong with it (input_files.check), rather than Click's usage error (exit 2) for an
    unreadable file."""
    for param in command.params:
        if isinstance(param, click.Option) and param.name in FILE_OUTPUTS and isinstance(param.type, click.Path):
            param.type = _FileOutput(param.type)
        elif isinstance(param.type, click.Path) and not param.type.exists:
            param.type.readable = False
    return command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="datmo")
@click.option("--debug", is_flag=True, help="Show the traceback of an error (also: environment DATMO_DEBUG=1).")
def cli(debug: bool) -> None:
    """datmo: detect, classify and track moving objects in 2D laser-scanner logs.

    Implements Castro, Nunes and Ruano (2004). Logs are MCAP files with ROS 2 messages,
    so Foxglove and `ros2 bag` open them.

    Example: datmo import ../shared/data/carmen/csail-corrected.log.gz -o csail.mcap
    """


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    from .base import outputs

    _safe_streams()
    try:
        with outputs.handle_signals():  # as early as can be: a SIGTERM while importing still cleans up
            cli.main(args=argv, prog_name="datmo")
    except BrokenPipeError:
        sys.exit(141)
    except KeyboardInterrupt:  # outside a command (Click would say "Aborted!" and exit 1)
        outputs.remove_live()
        sys.exit(130)
    except outputs.Terminated as exc:
        outputs.remove_live()
        sys.exit(exc.exit_code)
