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
    "evaluate": ("evaluate", "Score tracks against ground truth (CLEAR-MOT, IDF1)."),
    "train-legs": ("train_legs", "Train the learned leg detector on labelled scans; print held-out figures."),
}


_ARGS: list[str] = []


def invocation(command: str) -> str:
    """The command line that started this run, as `datmo ARGS...` (for provenance metadata)."""
    import shlex

    args = _ARGS or [command]
    return "datmo " + " ".join(shlex.quote(a) for a in args)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    click.echo(f"datmo: warning: {message}", err=True)


class CleanError(click.ClickException):
    """A DatmoError as Click shows it: one line on stderr, no traceback."""

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code

    def show(self, file=None) -> None:  # noqa: ANN001 - Click's signature
        click.echo(f"datmo: error: {self.format_message()}", err=True, file=file)


class LazyGroup(click.Group):
    """A group whose commands are imported on first use; DatmoError becomes a clean message."""

    def main(self, args=None, *rest, **kwargs):  # noqa: ANN001, ANN201 - Click's signature
        _ARGS[:] = list(sys.argv[1:] if args is None else args)
        return super().main(args, *rest, **kwargs)

    def invoke(self, ctx: click.Context):  # noqa: ANN201 - Click's signature
        import warnings

        from .errors import DatmoError

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("always", UserWarning)
                warnings.showwarning = _show_warning
                return super().invoke(ctx)
        except DatmoError as exc:
            raise CleanError(str(exc), exc.exit_code) from None

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
        return module.command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="datmo")
def cli() -> None:
    """datmo: detect, classify and track moving objects in 2D laser-scanner logs.

    Implements Castro, Nunes and Ruano (2004). Logs are MCAP files with ROS 2 messages,
    so Foxglove and `ros2 bag` open them.

    Example: datmo import ../shared/data/carmen/csail-corrected.log.gz -o csail.mcap
    """


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    try:
        cli.main(args=argv, prog_name="datmo")
    except BrokenPipeError:
        sys.exit(141)
