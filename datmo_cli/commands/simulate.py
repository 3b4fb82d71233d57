"""`datmo simulate`: an LMS200 in a scene, written as a log with /scan, ground truth and (moving sensor) /odom: the
options, one call of datmo_cli.api.simulate (workflows.simulating) and the line it says."""

from __future__ import annotations

from pathlib import Path

import click

from ..base.bounds import OPTIONS
from .options import force_option, output_option, quiet_option
from .types import laser_pose_option, option

SCENE_HELP = (
    "Built-in scene name (hall, corridor, crowd, static, patrol, following, lab-drive; see --list-scenes) "
    "or the path of a .toml scene file."
)
LMS_OPTIONS = ("angle", "resolution", "range_m", "units")


def _list_scenes(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    from ..sim.scene import builtin_scenes

    for name, text in builtin_scenes().items():
        click.echo(f"{name:10s} {text}")
    ctx.exit()


@click.command(name="simulate")
@click.option("--scene", metavar="NAME|PATH", default="hall", show_default=True, help=SCENE_HELP)
@output_option("The log to write: MCAP, or a ROS 1 bag when it ends in .bag (no ground truth there).")
@force_option()
@option(
    "--seed",
    bound=OPTIONS["seed"],
    default=0,
    show_default=True,
    help="Random seed (crowd paths, range noise); a seed always gives the same file.",
)
@option(
    "--duration", bound=OPTIONS["sim_duration"], default=None, help="Seconds to simulate [default: the scene's, 60 s]."
)
@option(
    "--rate",
    bound=OPTIONS["sim_rate"],
    default=None,
    help="Scans per second [default: the scene's, else 5] (an LMS200: at most 75 Hz at 1°, 37.5 Hz at 0.5°, "
    "18.75 Hz at 0.25°).",
)
@option("--people", bound=OPTIONS["people"], default=None, help="Walkers in a crowd scene [default: the scene's].")
@click.option(
    "--angle",
    type=click.Choice(["180", "100"]),
    default="180",
    show_default=True,
    help="The LMS200's field of view, degrees (a scene with its own [scanner] refuses the LMS200 options).",
)
@click.option(
    "--resolution",
    type=click.Choice(["1", "0.5", "0.25"]),
    default="0.5",
    show_default=True,
    help="Angular resolution, degrees (0.25 only with --angle 100).",
)
@click.option(
    "--range",
    "range_m",
    type=click.Choice(["8", "16", "32", "80"]),
    default="8",
    show_default=True,
    help="Range mode, metres.",
)
@click.option(
    "--units", type=click.Choice(["mm", "cm"]), default=None, help="Output units [default: mm, or cm with --range 80]."
)
@option("--noise", bound=OPTIONS["sim_noise"], default=0.01, show_default=True, help="Range noise sigma, metres.")
@click.option(
    "--list-scenes",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_list_scenes,
    help="List the built-in scenes and exit.",
)
@laser_pose_option()
@quiet_option
def command(
    scene: str,
    output: Path,
    force: bool,
    seed: int,
    duration: float | None,
    rate: float | None,
    people: int | None,
    angle: str,
    resolution: str,
    range_m: str,
    units: str | None,
    noise: float,
    laser_pose: tuple | None,
) -> None:
    """Simulate a SICK LMS200 in a scene and write a log with ground truth.

    The log holds /scan (sensor_msgs/LaserScan), /datmo/ground_truth (one message per scan: every
    object's class, position and velocity in the sensor and world frames, size, and whether beams hit
    it) and, when the scene moves the scanner (and does not leave its odometry out), /odom with /tf (odom ->
    base_link) and /tf_static (base_link -> laser). The scene's scanner pose is the laser's: with --laser-pose,
    /odom holds the base's poses under it (a scene with its own laser_pose places the base instead).
    The same seed always gives the same file.

    An OUTPUT ending in .bag is written as a ROS 1 bag, as a ROS 1 robot records it: /scan, /odom, and /tf with
    odom -> base_link and the laser's mount repeated (slash-prefixed frame names, no /tf_static), without ground
    truth (a ROS 1 bag cannot hold datmo_msgs: simulate the same scene and seed to an .mcap for it).

    Example: datmo simulate --scene hall --duration 60 -o hall.mcap
    """
    from .. import api
    from ..base.progress import say
    from ..cli import invocation

    ctx = click.get_current_context()
    given = {k for k in LMS_OPTIONS if ctx.get_parameter_source(k) != click.core.ParameterSource.DEFAULT}
    lms = {"angle": angle, "resolution": resolution, "range_m": range_m, "units": units}
    result = api.simulate(
        output,
        scene,
        force=force,
        seed=seed,
        duration=duration,
        rate=rate,
        people=people,
        noise=noise,
        laser_pose=laser_pose,
        command_line=invocation("simulate"),
        **{k: v if k in given else None for k, v in lms.items()},
    )
    say(result.summary)
