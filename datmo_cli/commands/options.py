"""Click options shared by several commands: --quiet, --config/--no-config, refusing `-o -` for logs."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import click

from ..progress import quiet_option

__all__ = ["config_options", "input_options", "no_stdout", "quiet_option"]

STDOUT = "-"


def no_stdout(what: str = "an MCAP log", give: str = "a file name") -> Callable:
    """An option callback refusing `-` (stdout) for an output that cannot go to a stream."""
    def callback(ctx: click.Context, param: click.Parameter, value):
        if value is not None and str(value) == STDOUT:
            from ..errors import OutputError

            raise OutputError(f"{param.opts[-1]} -: cannot write {what} to stdout; give {give}")
        return value
    return callback


def config_options(help: str) -> Callable:
    """`--config FILE` (help: `help`) and `--no-config`; the command receives `config`, the file to use:
    --config, else ./datmo.toml when present (said on stderr), else None (config.effective_path)."""
    def decorate(f: Callable) -> Callable:
        @functools.wraps(f)
        def wrapper(*args, config: Path | None = None, no_config: bool = False, **kwargs):
            from ..config import effective_path

            return f(*args, config=effective_path(config, no_config), **kwargs)

        wrapper = click.option("--no-config", is_flag=True,
                               help="Ignore ./datmo.toml: defaults and options only.")(wrapper)
        return click.option("--config", type=click.Path(dir_okay=False, path_type=Path), default=None,
                            help=f"{help} [default: ./datmo.toml when present]")(wrapper)
    return decorate


def input_options(f: Callable) -> Callable:
    """`--topic` and `--odom-topic`, for inputs that are bags (see scan_log)."""
    f = click.option("--odom-topic", default=None,
                     help="With a bag: its nav_msgs/Odometry topic [default: the only one, if any].")(f)
    return click.option("--topic", default=None,
                        help="With a bag (ROS 1 .bag, ROS 2 folder or .db3) or a foreign MCAP: the LaserScan topic to "
                             "take when there are several (the input is converted as by datmo import).")(f)
