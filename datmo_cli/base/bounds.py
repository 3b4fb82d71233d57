"""The allowed range of every numeric parameter, the one check of a value against it, and the one validator
of a config section.

Every `[features]` and `[track]` key has its Bound in its field's declaration (`param`, in perception/params.py
and tracking/params.py; `bounds_of` lists them) and every numeric command-line option that is not one of them
(OPTIONS) has a Bound here: its unit, its closed or open range and why the range ends where it does.
`check` refuses NaN, infinities, wrong types and values outside the range with a ConfigError naming the key
or option, the value and the range; `Bounded` (datmo_cli/commands/types.py) is the Click type built on it,
so a bad option is one line (`datmo: error: --gate: ...`, exit status 2 as for any bad option). The ranges
are wide enough for any scanner (a 30 m Hokuyo, an 80 m SICK, a big hall); what they exclude would hang a
kernel, allocate unbounded arrays or make no sense. Some parameters combine into an array's size or a
kernel's work (Hough accumulators, the background grid): `features_combined` and `track_combined` refuse
combinations above a limit, naming both parameters.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, ClassVar, Self, TypeVar

from .errors import ConfigError


@dataclass(frozen=True)
class Bound:
    """lo <= x <= hi (lo < x with lo_open), in `unit`; `why`: what the range protects, said in errors."""

    lo: float
    hi: float
    unit: str = ""
    why: str = ""
    lo_open: bool = False
    integer: bool = False

    def describe(self) -> str:
        """The range as help and errors show it, e.g. '0 < x ≤ 1000 m' or '2 ≤ n ≤ 16'."""
        x = "n" if self.integer else "x"
        text = f"{_show(self.lo)} {'<' if self.lo_open else '≤'} {x} ≤ {_show(self.hi)}"
        return f"{text} {self.unit}" if self.unit else text


class OptionError(ConfigError):
    """A command-line option's value is out of its range (exit status 2, as Click's usage errors)."""

    exit_code = 2


def _show(v: float) -> str:
    if isinstance(v, int) and not isinstance(v, bool):
        s = str(v)
        return s if len(s) <= 16 else f"a {len(s)}-digit number"
    return f"{v:g}"


def check(bound: Bound, value: object, name: str, error: type[ConfigError] = ConfigError) -> float | int:
    """`value` as a float (an int for an integer Bound) when it is a finite number within `bound`; else
    `error` naming `name` (the TOML key or the option), the value and the range."""
    want = "int" if bound.integer else "float"
    if isinstance(value, bool) or not isinstance(value, int | float) or (bound.integer and not isinstance(value, int)):
        raise error(f"{name}: expected {want}, got {value!r}")
    allowed = f"allowed: {bound.describe()}" + (f" ({bound.why})" if bound.why else "")
    if isinstance(value, float) and not math.isfinite(value):
        raise error(f"{name}: {value} is not a finite number; {allowed}")
    if value < bound.lo or (bound.lo_open and value == bound.lo):
        problem = (
            "must be positive"
            if bound.lo == 0 and bound.lo_open
            else f"must be {'above' if bound.lo_open else 'at least'} {_show(bound.lo)}"
        )
        raise error(f"{name}: {problem}, got {_show(value)}; {allowed}")
    if value > bound.hi:
        raise error(f"{name}: must be at most {_show(bound.hi)}, got {_show(value)}; {allowed}")
    return int(value) if bound.integer else float(value)


def _b(lo: float, hi: float, unit: str = "", why: str = "", *, open_: bool = False, integer: bool = False) -> Bound:
    return Bound(lo, hi, unit, why, open_, integer)


bound = _b  # for the parameter sections (perception/params.py, tracking/params.py)
# reasons a range ends where it does, shared by the sections and OPTIONS
SHARE = "a share"
PROBABILITY = "a probability"
NO_SENSE = "beyond any scanner's reach"


def param(
    default: object,
    bound: Bound | None = None,
    help: str = "",
    *,
    choices: tuple[str, ...] = (),
    same_as: str = "",
    metavar: str | None = None,
) -> Any:
    """A field of a parameter section with its metadata: `bound` (a number's range and unit), `help` (what it
    does, as the TOML comment and the option's help say it) and, for a string, the `choices` it takes (none:
    any non-empty string). The one declaration the validator, the Click options and `datmo config` read.
    `same_as` ('section.key'): the field is that parameter, whose home is there; the configuration tree sets
    it from its home (config.DatmoConfig), and a value written in this section is read as the home's.
    `metavar`: the option's value placeholder in help (default: from the type)."""
    return field(
        default=default,
        metadata={"bound": bound, "help": help, "choices": choices, "same_as": same_as, "metavar": metavar},
    )


@dataclass(frozen=True)
class Section:
    """A table of a config file (`[features]`, `[track]`): a frozen dataclass whose fields are declared with
    `param`. `renamed`: keys an older datmo read, each with the key that replaces it and why (an old config
    file using one is refused with the new name, not read with a changed meaning); `removed`: keys an older datmo
    read that no longer exist, each with why (refused, saying so)."""

    name: ClassVar[str]
    renamed: ClassVar[dict[str, str]] = {}
    removed: ClassVar[dict[str, str]] = {}

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **changes) -> Self:
        """A copy with `changes` (keys checked; None values ignored)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        return validate(type(self), {**self.to_dict(), **changes})

    @classmethod
    def combined(cls, params: Self, where: str) -> None:
        """ConfigError when values each in range contradict each other (see features_combined)."""


S = TypeVar("S", bound=Section)


def bounds_of(section: type[Section]) -> dict[str, Bound]:
    """The Bound of every numeric field of a section, by key."""
    return {f.name: f.metadata["bound"] for f in fields(section) if f.metadata.get("bound") is not None}


def validate(section: type[S], values: dict, where: str | None = None) -> S:
    """A section from a mapping, every key checked against its field's metadata (names, types, ranges,
    choices) and the combination checked (Section.combined); keys not given take their defaults. ConfigError
    names `where`.key (default: the section's name), the value and what is allowed."""
    where = where or section.name
    known = {f.name: f for f in fields(section)}
    out: dict[str, Any] = {}
    for key, value in values.items():
        if key in section.renamed:
            raise ConfigError(f"{where}.{key}: renamed to {section.renamed[key]}")
        if key in section.removed:
            raise ConfigError(f"{where}.{key}: no longer a parameter: {section.removed[key]}")
        if key not in known:
            raise ConfigError(f"{where}.{key}: unknown parameter (known: {', '.join(sorted(known))})")
        meta = known[key].metadata
        if meta["bound"] is not None:
            out[key] = check(meta["bound"], value, f"{where}.{key}")
        elif meta["choices"]:
            if value not in meta["choices"]:
                raise ConfigError(f"{where}.{key}: one of {', '.join(meta['choices'])}; got {value!r}")
            out[key] = value
        else:
            if not isinstance(value, str) or not value.strip():
                raise ConfigError(f"{where}.{key}: must be a non-empty string, got {value!r}")
            out[key] = value
    params = section(**out)
    section.combined(params, where)
    ordered_pairs(params, where)
    return params


def min_max_pairs(section: type[Section]) -> list[tuple[str, str]]:
    """The (minimum, maximum) pairs of a section's numeric fields, by name: X_min and X_max, X_min_Y and
    X_max_Y, min_X and max_X (circle_radius_min and circle_radius_max, step_min and step_max,
    bench_min_length and bench_max_length)."""
    numeric = bounds_of(section)
    pairs = []
    for name in numeric:
        if name.endswith("_min"):
            other = name[: -len("_min")] + "_max"
        elif "_min_" in name:
            other = name.replace("_min_", "_max_", 1)
        elif name.startswith("min_"):
            other = "max_" + name[len("min_") :]
        else:
            continue
        if other in numeric:
            pairs.append((name, other))
    return pairs


def ordered_pairs(params: Section, where: str) -> None:
    """ConfigError when a minimum is above its maximum (min_max_pairs): no value could lie between them."""
    bounds = bounds_of(type(params))
    for lo, hi in min_max_pairs(type(params)):
        a, b = getattr(params, lo), getattr(params, hi)
        if a > b:
            unit = f" {bounds[lo].unit}" if bounds[lo].unit else ""
            raise ConfigError(
                f"{where}.{lo}: {_show(a)}{unit} is above {hi} = {_show(b)}{unit}; a minimum must be "
                f"at most its maximum"
            )


D_MAX = _b(0, 100, "m", NO_SENSE, open_=True)  # the paper's d_max: features.d_max, read by tracking too
_SIM_HOUR = "an hour of scans; the world's paths are planned for the whole run up front"
# options that are not `[features]` or `[track]` keys (and the scene files' duration and crowd size)
OPTIONS: dict[str, Bound] = {
    "seed": _b(0, 2**63 - 1, "", "a 63-bit seed", integer=True),
    "sim_duration": _b(0, 3600, "s", _SIM_HOUR, open_=True),
    "sim_rate": _b(0, 75, "Hz", "the LMS200's fastest rate (at 1°; finer resolutions allow less)", open_=True),
    "sim_noise": _b(0, 1, "m", "range noise sigma"),
    "people": _b(0, 100, "walkers", "each walker's path avoids the earlier ones", integer=True),
    "record_duration": _b(0, 31_536_000, "s", "a year", open_=True),
    "scans": _b(1, 10**12, "scans", integer=True),
    "threads": _b(1, 1024, "threads", integer=True),
    "jobs": _b(1, 1024, "processes", integer=True),
    "retries": _b(0, 100, "retries", integer=True),
    "trials": _b(1, 100_000, "trials", "each trial scores every log at least once", integer=True),
    "top": _b(0, 10**9, "tracks", "0: all", integer=True),
    "match_radius": _b(0, 100, "m", NO_SENSE, open_=True),
    "min_mota": _b(-100, 1, "", "MOTA is at most 1"),
    "min_hota": _b(0, 1, "", "HOTA is a share"),
    "live_port": _b(0, 65535, "", "a TCP port; 0: any free one", integer=True),
    "play_rate": _b(0, 1000, "× the log's speed", "beyond 1000× a scan log is a blur", open_=True),
    "laser_offset": _b(-100, 100, "m", "the scanner sits on the robot"),
    "laser_yaw": _b(-360, 360, "degrees"),
    "domain_id": _b(0, 232, "", "ROS 2's domain ids (DDS ports beyond 232 overflow)", integer=True),
}

LINE_ACCUMULATOR_CELLS = 2**25  # theta x rho cells of the HTL accumulator, int32, one per thread (128 MB)
LINE_RANGE_M = 100.0  # the kernels size the rho axis for ranges up to this (min(range_max, 100))
CIRCLE_VOTES = 2**18  # radii x (a, b) cells a point votes over in the HTC (the kernel's work)
BACKGROUND_SIDE = 2048  # cells along a side of the tracker's background grid (16 bytes a cell)


def line_accumulator_cells(theta_resolution: float, rho_resolution: float) -> int:
    """Cells of the HTL accumulator: theta cells over 180° times rho cells over ±LINE_RANGE_M (degrees, m)."""
    nt = max(int(round(180.0 / theta_resolution)), 1)
    return nt * (int(2.0 * LINE_RANGE_M / rho_resolution) + 3)


def circle_votes(radius_min: float, radius_max: float, radius_step: float, window: float, cell: float) -> int:
    """Radii voted for times the (a, b) cells of the HTC window, each point's share of the work (m)."""
    radii = int(math.floor((radius_max - radius_min) / radius_step + 1e-9)) + 1
    side = 2 * int(round(window / cell)) + 1
    return radii * side * side


def background_side(extent: float, cell: float) -> int:
    """Cells along a side of the background grid spanning ±extent (m) in cells of `cell` (m)."""
    return int(math.ceil(2.0 * extent / cell))


def features_combined(p, where: str = "features") -> None:
    """ConfigError when parameters that are each in range combine into a contradiction or too big a kernel."""
    if p.circle_radius_min >= p.circle_radius_max:
        raise ConfigError(f"{where}: circle_radius_min must be below circle_radius_max")
    if p.bench_min_length >= p.bench_max_length:
        raise ConfigError(f"{where}: bench_min_length must be below bench_max_length")
    cells = line_accumulator_cells(p.theta_resolution, p.rho_resolution)
    if cells > LINE_ACCUMULATOR_CELLS:
        raise ConfigError(
            f"{where}: theta_resolution {p.theta_resolution:g}° and rho_resolution "
            f"{p.rho_resolution:g} m make a line accumulator of {cells:,} cells (at most "
            f"{LINE_ACCUMULATOR_CELLS:,}); raise either"
        )
    votes = circle_votes(p.circle_radius_min, p.circle_radius_max, p.circle_radius_step, p.circle_window, p.circle_cell)
    if votes > CIRCLE_VOTES:
        raise ConfigError(
            f"{where}: circle_radius_step {p.circle_radius_step:g} m (radii from "
            f"{p.circle_radius_min:g} to {p.circle_radius_max:g} m) and circle_cell {p.circle_cell:g} m "
            f"(window {p.circle_window:g} m) make {votes:,} circle votes per point (at most "
            f"{CIRCLE_VOTES:,}); raise circle_radius_step or circle_cell"
        )


def track_combined(p, where: str = "track") -> None:
    """ConfigError when tracking parameters that are each in range contradict or make too big a grid."""
    if p.confirm_window < p.confirm_hits:
        raise ConfigError(f"{where}.confirm_window: must be at least confirm_hits ({p.confirm_hits})")
    side = background_side(p.background_extent, p.background_cell)
    if p.background_time > 0 and side > BACKGROUND_SIDE:
        raise ConfigError(
            f"{where}: background_extent {p.background_extent:g} m and background_cell "
            f"{p.background_cell:g} m make a background grid {side:,} cells a side (at most "
            f"{BACKGROUND_SIDE:,}); raise background_cell or lower background_extent"
        )
