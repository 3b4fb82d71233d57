"""`datmo node`'s ROS 2 parameters: datmo's configuration keys, named `section.key` (`track.gate`,
`features.d_max`), each with its value, type, range and help, as the parameter services give them; and which
may change while the node runs.

A parameter may change live when the running tracker reads it on each scan and no array was sized from it:
the tracking kernels' parameters (tracking.state.PARAM_NAMES) but those that size the track table's tails, the
background grid or the free-space scans, and d_max (its home is [features]). The others are read when the
stages start (the perception's, the leg model, hindsight_lag: the node is causal anyway, ego_motion): a change
is refused with that reason. A value is checked as a config file's (bounds.validate: the same ranges and
messages). Units are the keys' own (metres, seconds, m/s; see `datmo config`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..base.bounds import Bound, validate
from ..base.errors import ConfigError
from ..passes.config import SECTIONS, DatmoConfig, same_as
from ..tracking.state import PARAM_NAMES

NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4  # rcl_interfaces/msg/ParameterType
SIZED = ("tail_length", "background_time", "background_cell", "background_extent", "free_space_scans", "d_max")
LIVE = frozenset(f"track.{name}" for name in PARAM_NAMES if name not in SIZED)
DEPTH_RECURSIVE = 0  # rcl_interfaces/srv/ListParameters


@dataclass(frozen=True)
class Description:
    """What describe_parameters tells of one parameter: its ROS 2 type (INTEGER, DOUBLE, STRING), help, the
    allowed values as text, whether it is read-only (not live) and its range (None: no numeric range)."""

    name: str
    type: int
    description: str
    constraints: str
    read_only: bool
    bound: Bound | None


class Parameters:
    """datmo's configuration as ROS 2 parameters: `names()`, `get(name)`, `describe(name)`, `set(name, value)`.
    `config` is the node's configuration, replaced by each accepted change."""

    def __init__(self, config: DatmoConfig | None = None) -> None:
        self.config = config or DatmoConfig()
        self._fields = {
            f"{s}.{f.name}": f
            for s, cls in SECTIONS.items()
            for f in fields(cls)  # type: ignore[arg-type]
            if f.name not in same_as(cls)
        }

    def names(self) -> list[str]:
        """Every parameter, `section.key`, in the sections' order."""
        return list(self._fields)

    def list(self, prefixes: list[str], depth: int = DEPTH_RECURSIVE) -> tuple[list[str], list[str]]:
        """(names, prefixes) as rcl_interfaces/srv/ListParameters answers: the names under any of `prefixes`
        (all when none) with fewer than `depth` dots below the prefix (any when DEPTH_RECURSIVE), and the
        prefixes of the dotted ones."""
        out = []
        for name in self._fields:
            if prefixes:
                under = [name[len(p) + 1 :] for p in prefixes if name.startswith(p + ".")]
                if not under:
                    continue
                rest = min(under, key=len)
            else:
                rest = name
            if depth == DEPTH_RECURSIVE or rest.count(".") < depth:
                out.append(name)
        return out, sorted({n.rpartition(".")[0] for n in out if "." in n})

    def get(self, name: str) -> object:
        """The value of `name` (a float, an int or a str); None for an unknown name."""
        return self.config.get(name) if name in self._fields else None

    def describe(self, name: str) -> Description | None:
        f = self._fields.get(name)
        if f is None:
            return None
        meta = f.metadata
        bound, choices = meta.get("bound"), meta.get("choices") or ()
        kind = STRING if bound is None else INTEGER if bound.integer else DOUBLE
        if bound is not None:
            constraints = bound.describe() + (f" ({bound.why})" if bound.why else "")
        else:
            constraints = f"one of {', '.join(choices)}" if choices else "a non-empty string"
        if name not in LIVE:
            constraints += "; read when the node starts: set it in the config file"
        return Description(name, kind, meta.get("help", ""), constraints, name not in LIVE, bound)

    def set(self, name: str, value: object) -> str:
        """Set `name` to `value` when it may change live and the value is allowed; returns "" then, else the
        reason it was refused (the config file's message for a value out of range)."""
        if name not in self._fields:
            return _unknown(name)
        if value is None:
            return f"{name}: a parameter of datmo cannot be undeclared"
        if name not in LIVE:
            return (
                f"{name}: read when the node starts, not while it runs: set it in the config file and start "
                "datmo node again"
            )
        section, _, key = name.partition(".")
        if isinstance(value, int) and not isinstance(value, bool) and not self._fields[name].metadata["bound"].integer:
            value = float(value)  # `ros2 param set /datmo track.gate 12` sends an integer
        try:
            self.config = self.config.replace(**{section: {key: value}})
        except ConfigError as exc:
            return str(exc)
        return ""


def _unknown(name: str) -> str:
    """Why `name` is no parameter: the config file's message for an unknown, renamed or removed key."""
    section, _, key = name.partition(".")
    cls = SECTIONS.get(section)
    if cls is None:
        return f"{name}: unknown parameter (datmo's are {' and '.join(f'{s}.KEY' for s in SECTIONS)})"
    home = same_as(cls).get(key)
    if home:
        return f"{name}: the same parameter as {home}, its home: set {home}"
    try:
        validate(cls, {key: 0})
    except ConfigError as exc:
        return str(exc)
    return f"{name}: unknown parameter"
