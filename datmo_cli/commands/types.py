"""The Click pieces built on the lower layers, so that only the CLI layer imports click: the number types
checked against a Bound (bounds.py), --laser-pose, --quiet (progress.py), and the running command's shared
state (Click's context meta) handed to progress.command_meta."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import click
from click.decorators import FC

from ..base import progress
from ..base.bounds import OPTIONS, Bound, OptionError, check

__all__ = ["Bounded", "LaserPose", "laser_pose_option", "option", "option_name", "pair_option", "quiet_option"]


def _click_meta() -> dict[str, Any] | None:
    """The running Click command's meta (shared by a command and its group), None outside a command."""
    ctx = click.get_current_context(silent=True)
    return None if ctx is None else ctx.meta


progress.use_command_meta(_click_meta)


def _set_quiet(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    ctx.meta[progress.QUIET_KEY] = bool(value)


def quiet_option(f: Callable) -> Callable:
    """The `-q/--quiet` option: no progress bars and no informational lines; warnings and errors are still
    printed on stderr, and a command's result (tables, JSON, CSV on stdout) is still printed."""
    return click.option(
        "-q",
        "--quiet",
        is_flag=True,
        expose_value=False,
        is_eager=True,
        callback=_set_quiet,
        help="No progress and no informational output (warnings and errors still go to stderr).",
    )(f)


def option_name(param: click.Parameter | None) -> str:
    """An option as the user typed it: its longest flag ('--gate'), or its name."""
    if param is None:
        return "value"
    flags = [o for o in getattr(param, "opts", []) if o.startswith("-")]
    return max(flags, key=len) if flags else (param.name or "value")


class Bounded(click.ParamType):
    """A number within a Bound; a bad value is one line naming the option and the range (OptionError)."""

    def __init__(self, bound: Bound) -> None:
        self.bound = bound
        self.name = "integer" if bound.integer else "float"

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "INTEGER" if self.bound.integer else "FLOAT"

    def convert(self, value, param, ctx):
        name = option_name(param)
        if isinstance(value, str):
            text = value.strip()
            try:
                value = int(text) if self.bound.integer else float(text)
            except ValueError:
                kind = "a whole number" if self.bound.integer else "a number"
                raise OptionError(f"{name}: expected {kind}, got {text!r}; allowed: {self.bound.describe()}") from None
        return check(self.bound, value, name, OptionError)


def option(*decls: str, bound: Bound, help: str, **kwargs) -> Callable[[FC], FC]:
    """click.option for a number within `bound`, the range appended to its help."""
    return click.option(*decls, type=Bounded(bound), help=f"{help} Range: {bound.describe()}.", **kwargs)


def pair_option(
    *decls: str, bounds: tuple[Bound, Bound], names: tuple[str, str], help: str, **kwargs
) -> Callable[[FC], FC]:
    """click.option taking two numbers (e.g. MIN MAX), each within its bound, the ranges appended to its help."""
    ranges = ", ".join(f"{n} {b.describe()}" for n, b in zip(names, bounds, strict=True))
    return click.option(
        *decls,
        type=click.Tuple([Bounded(bounds[0]), Bounded(bounds[1])]),
        metavar=" ".join(names),
        help=f"{help} Range: {ranges}.",
        **kwargs,
    )


class LaserPose(click.ParamType):
    """`X,Y,YAW`: where the scanner sits on the robot (metres, metres, degrees), each within its Bound; the value
    is (x, y, yaw in radians)."""

    name = "pose"
    parts = (("x", OPTIONS["laser_offset"]), ("y", OPTIONS["laser_offset"]), ("yaw", OPTIONS["laser_yaw"]))

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "X,Y,YAW"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        name = option_name(param)
        fields = str(value).split(",")
        if len(fields) != 3:
            raise OptionError(f"{name}: expected X,Y,YAW (metres, metres, degrees), got {value!r}")
        out = []
        for text, (part, bound) in zip(fields, self.parts, strict=True):
            try:
                number = float(text.strip())
            except ValueError:
                raise OptionError(
                    f"{name}: {part} is not a number, got {text.strip()!r}; expected X,Y,YAW (metres, metres, degrees)"
                ) from None
            out.append(check(bound, number, f"{name} {part}", OptionError))
        return out[0], out[1], math.radians(out[2])


def laser_pose_option() -> Callable[[FC], FC]:
    """--laser-pose X,Y,YAW (see LaserPose)."""
    ranges = ", ".join(f"{part} {bound.describe()}" for part, bound in LaserPose.parts)
    return click.option(
        "--laser-pose",
        type=LaserPose(),
        default=None,
        help="Where the scanner sits on the robot: X,Y in metres and YAW in degrees, in the base frame "
        f"(base_link); written to /tf_static and the metadata (datmo.laser_pose). "
        f"Range: {ranges}.",
    )
