"""Click options shared by the commands: -o/--output, --force, --config/--no-config with the parameter options
built from the configuration's fields, --quiet, the bag inputs' --topic and --odom-topic, and the batch executor's
-j/--jobs, --scheduler and --retries (datmo run and datmo tune)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path

import click

from .types import quiet_option

__all__ = [
    "config_options",
    "executor_options",
    "force_option",
    "input_options",
    "no_stdout",
    "output_option",
    "param_option",
    "param_pair_option",
    "quiet_option",
]

STDOUT = "-"
OPTIONS_KEY = "datmo.param_options"  # in the Click context's meta: section -> key -> value given as an option


def no_stdout(what: str = "an MCAP log", give: str = "a file name") -> Callable:
    """An option callback refusing `-` (stdout) for an output that cannot go to a stream."""

    def callback(ctx: click.Context, param: click.Parameter, value):
        if value is not None and str(value) == STDOUT:
            from ..base.errors import OutputError

            raise OutputError(f"{param.opts[-1]} -: cannot write {what} to stdout; give {give}")
        return value

    return callback


def output_option(help: str, *decls: str, dash: bool = False, file: bool = True, **kwargs) -> Callable:
    """`-o/--output PATH` (or `decls`; help: `help`), required unless a default is given; `-` (stdout) refused
    (no_stdout) unless `dash`; `file`: a file, not a folder. `kwargs` go to click.option (e.g. type=str for
    an fsspec URL, callback=no_stdout(what, give) for another refusal, default=STDOUT)."""
    kwargs.setdefault("required", "default" not in kwargs)
    if not dash:
        kwargs.setdefault("callback", no_stdout())
    kwargs.setdefault("type", click.Path(dir_okay=not file, allow_dash=dash, path_type=Path))
    return click.option(*(decls or ("-o", "--output")), help=help, **kwargs)


def force_option(help: str = "Overwrite the output if it exists.") -> Callable:
    """`--force` (help: `help`)."""
    return click.option("--force", is_flag=True, help=help)


def config_options(help: str, *, path: bool = False) -> Callable:
    """`--config FILE` (help: `help`) and `--no-config`; the command receives `cfg`, the DatmoConfig it runs
    with: the defaults, overridden by --config (else ./datmo.toml when present, said on stderr; see
    config.effective_path), overridden by the parameter options given (param_option); with `path`, also
    `config`, the file read (None: none)."""

    def decorate(f: Callable) -> Callable:
        @functools.wraps(f)
        def wrapper(*args, config: Path | None = None, no_config: bool = False, **kwargs):
            from ..passes import config as configuration

            ctx = click.get_current_context()
            file = configuration.effective_path(config, no_config)
            cfg = configuration.load(file, ctx.meta.get(OPTIONS_KEY))
            return f(*args, cfg=cfg, **({"config": file} if path else {}), **kwargs)

        wrapper = click.option("--no-config", is_flag=True, help="Ignore ./datmo.toml: defaults and options only.")(
            wrapper
        )
        return click.option(
            "--config",
            type=click.Path(dir_okay=False, path_type=Path),
            default=None,
            help=f"{help} [default: ./datmo.toml when present]",
        )(wrapper)

    return decorate


def _field(key: str):
    """The section and the dataclass field of 'section.key' (e.g. 'track.gate')."""
    from ..passes.config import SECTIONS

    section, _, name = key.partition(".")
    by_name = {f.name: f for f in fields(SECTIONS[section])}
    return section, by_name[name]


def _keep(*keys: str) -> Callable:
    """An option callback keeping its value (a tuple for several keys) for config_options; the value is
    returned as well, for an option the command also receives (param_option's `expose`)."""

    def callback(ctx: click.Context, _param: click.Parameter, value):
        if value is None:
            return None
        for key, v in zip(keys, value if len(keys) > 1 else (value,), strict=True):
            section, f = _field(key)
            ctx.meta.setdefault(OPTIONS_KEY, {}).setdefault(section, {})[f.name] = v
        return value

    return callback


def _default(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def param_option(key: str, *decls: str, help: str | None = None, expose: bool = False) -> Callable:
    """The option setting configuration parameter `key` ('section.name', e.g. 'track.gate'), built from its
    field: `--name` (or `decls`), its type from the field's Bound (or choices), its help the field's help (or
    `help`) with the default and the range. The value goes to the DatmoConfig config_options makes (the
    command gets `cfg`, not the option), overriding the config file; with `expose` the command also gets the
    option's value as given (None: not given), for a command that treats an explicit value apart."""
    from .types import Bounded

    _, f = _field(key)
    meta = f.metadata
    decls = decls or (f"--{f.name.replace('_', '-')}",)
    text = f"{(help or meta['help']).rstrip('.')} [default: {_default(f.default)}]"
    kind: click.ParamType | type[str]
    if meta["bound"] is not None:
        kind, text = Bounded(meta["bound"]), f"{text}. Range: {meta['bound'].describe()}."
    elif meta["choices"]:
        kind, text = click.Choice(meta["choices"]), f"{text}."
    else:
        kind, text = str, f"{text}."
    return click.option(
        *decls,
        f.name,
        type=kind,
        default=None,
        expose_value=expose,
        callback=_keep(key),
        help=text,
        metavar=meta["metavar"],
    )


def param_pair_option(decl: str, first: str, second: str, names: tuple[str, str], help: str) -> Callable:
    """One option setting two numeric parameters (e.g. --circle-radius MIN MAX: features.circle_radius_min and
    features.circle_radius_max), each within its field's Bound; help: `help` with both defaults and ranges."""
    from .types import Bounded

    (_, a), (_, b) = _field(first), _field(second)
    bounds = (a.metadata["bound"], b.metadata["bound"])
    ranges = ", ".join(f"{n} {bd.describe()}" for n, bd in zip(names, bounds, strict=True))
    return click.option(
        decl,
        type=click.Tuple([Bounded(bounds[0]), Bounded(bounds[1])]),
        metavar=" ".join(names),
        default=None,
        expose_value=False,
        callback=_keep(first, second),
        help=f"{help.rstrip('.')} [default: {_default(a.default)} {_default(b.default)}]. Range: {ranges}.",
    )


def input_options(f: Callable) -> Callable:
    """`--topic` and `--odom-topic`, for inputs that are bags (see scan_log)."""
    f = click.option(
        "--odom-topic", default=None, help="With a bag: its nav_msgs/Odometry topic [default: the only one, if any]."
    )(f)
    return click.option(
        "--topic",
        default=None,
        help="With a bag (ROS 1 .bag, ROS 2 folder or .db3) or a foreign MCAP: the LaserScan topic to "
        "take when there are several (the input is converted as by datmo import).",
    )(f)


def executor_options(units: str, task: str, tasks: str) -> Callable:
    """`-j/--jobs`, `--scheduler` and `--retries`: where a batch's tasks run (batch.LocalExecutor or
    cluster.DaskExecutor), one declaration for datmo run and datmo tune. `units`: what runs at once ("Inputs
    processed"), `task`: one task ("a task"), `tasks`: what runs on a scheduler ("one task per input")."""
    from ..base.bounds import OPTIONS
    from .types import option

    def decorate(f: Callable) -> Callable:
        f = option(
            "--retries",
            bound=OPTIONS["retries"],
            default=2,
            show_default=True,
            help=f"With --scheduler: times {task} is retried after an unexpected error or the death of its worker.",
        )(f)
        f = click.option(
            "--scheduler",
            metavar="ADDRESS",
            default=None,
            help=f"Run {tasks} on a running Dask scheduler (tcp://host:8786, tls://...), or on a local cluster of N "
            "worker processes started for the run (local[:N]). Needs pip install 'datmo-cli[dask]'; see docs/batch.md.",
        )(f)
        return option(
            "-j",
            "--jobs",
            bound=OPTIONS["jobs"],
            default=None,
            help=f"{units} at once, in separate processes on this machine [default: all cores].",
        )(f)

    return decorate
