"""Click options shared by the commands: -o/--output, --force, --config/--no-config with the parameter options
built from the configuration's fields, --quiet, the bag inputs' --topic and --odom-topic."""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import fields
from pathlib import Path

import click

from ..progress import quiet_option

__all__ = ["config_options", "force_option", "input_options", "needs_conversion", "no_stdout", "output_option",
           "param_option", "param_pair_option", "quiet_option", "scan_log"]

STDOUT = "-"
OPTIONS_KEY = "datmo.param_options"   # in the Click context's meta: section -> key -> value given as an option


def no_stdout(what: str = "an MCAP log", give: str = "a file name") -> Callable:
    """An option callback refusing `-` (stdout) for an output that cannot go to a stream."""
    def callback(ctx: click.Context, param: click.Parameter, value):
        if value is not None and str(value) == STDOUT:
            from ..errors import OutputError

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
            from .. import config as configuration

            ctx = click.get_current_context()
            file = configuration.effective_path(config, no_config)
            cfg = configuration.load(file, ctx.meta.get(OPTIONS_KEY))
            return f(*args, cfg=cfg, **({"config": file} if path else {}), **kwargs)

        wrapper = click.option("--no-config", is_flag=True,
                               help="Ignore ./datmo.toml: defaults and options only.")(wrapper)
        return click.option("--config", type=click.Path(dir_okay=False, path_type=Path), default=None,
                            help=f"{help} [default: ./datmo.toml when present]")(wrapper)
    return decorate


def _field(key: str):
    """The section and the dataclass field of 'section.key' (e.g. 'track.gate')."""
    from ..config import SECTIONS

    section, _, name = key.partition(".")
    by_name = {f.name: f for f in fields(SECTIONS[section])}
    return section, by_name[name]


def _keep(*keys: str) -> Callable:
    """An option callback keeping its value (a tuple for several keys) for config_options, not for the
    command's parameters."""
    def callback(ctx: click.Context, _param: click.Parameter, value) -> None:
        if value is None:
            return
        for key, v in zip(keys, value if len(keys) > 1 else (value,), strict=True):
            section, f = _field(key)
            ctx.meta.setdefault(OPTIONS_KEY, {}).setdefault(section, {})[f.name] = v
    return callback


def _default(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def param_option(key: str, *decls: str, help: str | None = None) -> Callable:
    """The option setting configuration parameter `key` ('section.name', e.g. 'track.gate'), built from its
    field: `--name` (or `decls`), its type from the field's Bound (or choices), its help the field's help (or
    `help`) with the default and the range. The value goes to the DatmoConfig config_options makes (the
    command gets `cfg`, not the option), overriding the config file."""
    from ..bounds import Bounded

    _, f = _field(key)
    meta = f.metadata
    decls = decls or (f"--{f.name.replace('_', '-')}",)
    text = f"{(help or meta['help']).rstrip('.')} [default: {_default(f.default)}]"
    if meta["bound"] is not None:
        kind, text = Bounded(meta["bound"]), f"{text}. Range: {meta['bound'].describe()}."
    elif meta["choices"]:
        kind, text = click.Choice(meta["choices"]), f"{text}."
    else:
        kind, text = str, f"{text}."
    extra = {"metavar": "MODEL"} if f.name == "leg_model" else {}
    return click.option(*decls, f.name, type=kind, default=None, expose_value=False, callback=_keep(key),
                        help=text, **extra)


def param_pair_option(decl: str, first: str, second: str, names: tuple[str, str], help: str) -> Callable:
    """One option setting two numeric parameters (e.g. --circle-radius MIN MAX: features.circle_radius_min and
    features.circle_radius_max), each within its field's Bound; help: `help` with both defaults and ranges."""
    from ..bounds import Bounded

    (_, a), (_, b) = _field(first), _field(second)
    bounds = (a.metadata["bound"], b.metadata["bound"])
    ranges = ", ".join(f"{n} {bd.describe()}" for n, bd in zip(names, bounds, strict=True))
    return click.option(decl, type=click.Tuple([Bounded(bounds[0]), Bounded(bounds[1])]), metavar=" ".join(names),
                        default=None, expose_value=False, callback=_keep(first, second),
                        help=f"{help.rstrip('.')} [default: {_default(a.default)} {_default(b.default)}]. "
                             f"Range: {ranges}.")


def input_options(f: Callable) -> Callable:
    """`--topic` and `--odom-topic`, for inputs that are bags (see scan_log)."""
    f = click.option("--odom-topic", default=None,
                     help="With a bag: its nav_msgs/Odometry topic [default: the only one, if any].")(f)
    return click.option("--topic", default=None,
                        help="With a bag (ROS 1 .bag, ROS 2 folder or .db3) or a foreign MCAP: the LaserScan topic to "
                             "take when there are several (the input is converted as by datmo import).")(f)


@contextmanager
def scan_log(src: Path, output: Path, topic: str | None = None, odom_topic: str | None = None, *,
             force: bool = False, dest: Path | None = None,
             tell: Callable[[str], None] | None = None) -> Iterator[Path]:
    """The datmo log to read for `src`: `src` itself when it is an MCAP file and no topic is chosen; otherwise
    (a ROS 1 or ROS 2 bag, a CARMEN log, or a topic chosen) `src` converted as by `datmo import` into a
    temporary MCAP beside `output`, said on stderr and removed when the block ends (or on any way out).
    Before converting, `output` is checked (check_output with `force`): a refused output costs no conversion.
    `dest`: the temporary MCAP's path (default: a hidden name beside `output`); `tell`: what gets the lines
    said (the conversion, warnings), e.g. a batch task's record (default: stderr, the conversion unless --quiet)."""
    from .. import outputs
    from ..log.importers import detect_kind, open_import, write_import
    from ..progress import say

    src = _bag_folder(Path(src))
    if not needs_conversion(src, topic, odom_topic):
        yield src   # an MCAP (or not a log at all: the reader says what is wrong with it)
        return
    detect_kind(src)   # a missing file, a folder without metadata.yaml: one line
    outputs.check_output(output, force=force, inputs=[src])
    tmp = dest if dest is not None else outputs.temp_path(Path(output))
    outputs.track(tmp)
    try:
        folder = outputs.folder_of(Path(output))
        stream = open_import(src, topic, odom_topic=odom_topic, spool_dir=folder)
        try:
            stats = write_import(stream, tmp, force=True)
        finally:
            for w in stream.warnings:
                (tell or functools.partial(click.echo, err=True))(f"datmo: warning: {w}")
        odom = f" and {stats.poses} poses from {stream.odom_topic}" if stats.poses else ""
        kind = {"ros1": "ROS 1 bag", "ros2": "ROS 2 bag"}.get(stream.kind, stream.kind)
        (tell or say)(f"datmo: converted {src} ({kind}: {stats.scans} scans from {stream.topic}{odom}) to a "
                      "temporary MCAP")
        yield tmp
    finally:
        outputs.discard(tmp)


def needs_conversion(src: Path, topic: str | None = None, odom_topic: str | None = None) -> bool:
    """Whether `src` is read through the importers: a bag (ROS 1 file, ROS 2 folder or its .db3) or a topic
    chosen; a datmo MCAP is read as it is."""
    src = Path(src)
    return (topic is not None or odom_topic is not None or src.is_dir() or src.suffix == ".db3"
            or _is_ros1_bag(src))


def _bag_folder(src: Path) -> Path:
    """A ROS 2 bag's .db3 (or .mcap) file as its folder when the folder holds the bag's metadata.yaml."""
    if src.suffix == ".db3":
        if not (src.parent / "metadata.yaml").is_file():
            from ..errors import InputError

            raise InputError(f"{src}: a ROS 2 .db3 is read with its bag folder, and {src.parent} has no "
                             "metadata.yaml")
        return src.parent
    return src


def _is_ros1_bag(src: Path) -> bool:
    from ..log.importers import _ROSBAG1_MAGIC

    try:
        with open(src, "rb") as f:
            return f.read(len(_ROSBAG1_MAGIC)) == _ROSBAG1_MAGIC
    except OSError:
        return False
