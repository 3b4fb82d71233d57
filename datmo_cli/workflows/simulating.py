"""`datmo simulate`'s work as a call (datmo_cli.api.simulate): an LMS200 (or a scene's own scanner) in a scene,
written as a log with /scan (ranges in metres, sensor frame: x forward, y left), /datmo/ground_truth (every
object in the sensor and world frames) and, when the scene moves the scanner, /odom with /tf and /tf_static;
or as a ROS 1 bag (no ground truth). The command keeps what it prints."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..logs.scan import ScanGeometry

LMS_OPTIONS = ("angle", "resolution", "range_m", "units")  # the LMS200's settings, refused by a scene's [scanner]


@dataclass
class SimulateResult:
    """What a simulation wrote: `output`, its `scans`, the ground-truth `objects`, the scans' `geometry`
    (angles in radians, ranges in metres), and `bag` (a ROS 1 bag, without ground truth)."""

    output: Path
    scans: int
    objects: int
    geometry: ScanGeometry
    bag: bool

    @property
    def summary(self) -> str:
        """The line `datmo simulate` says."""
        if self.bag:
            return (
                f"{self.output}: ROS 1 bag, {self.scans} scans of {self.geometry.describe()}; no ground truth "
                "(write an .mcap for it)"
            )
        return f"{self.output}: {self.scans} scans of {self.geometry.describe()}, {self.objects} ground-truth objects"


def simulate(
    output: str | os.PathLike,
    scene: str = "hall",
    *,
    force: bool = False,
    seed: int = 0,
    duration: float | None = None,
    rate: float | None = None,
    people: int | None = None,
    angle: int | str | None = None,
    resolution: float | str | None = None,
    range_m: int | str | None = None,
    units: str | None = None,
    noise: float = 0.01,
    laser_pose: tuple[float, float, float] | None = None,
    command_line: str | None = None,
) -> SimulateResult:
    """`datmo simulate --scene SCENE -o OUTPUT`: simulate `scene` (a built-in name, sim.scene.builtin_scenes, or
    a .toml scene file) into `output`, an MCAP log with ground truth, or a ROS 1 bag when it ends in .bag.
    `seed` (the same seed gives the same file), `duration` s and `rate` Hz (None: the scene's), `people` in a
    crowd scene, `noise` the range noise sigma (m). The LMS200's `angle` (180 or 100 degrees), `resolution`
    (1, 0.5, 0.25 degrees), `range_m` (8, 16, 32, 80) and `units` ("mm", "cm"; None: cm at 80 m, else mm):
    None is the default (180, 0.5, 8); a scene with its own [scanner] refuses them (OptionError).
    `laser_pose` (x m, y m, yaw rad): the scanner on the robot. A progress bar on stderr in a terminal.
    `command_line` goes into the provenance. Returns the SimulateResult."""
    from ..base.bounds import OptionError
    from ..base.progress import bar
    from ..logs import mcapio
    from ..passes.simulated import write_simulation, write_simulation_bag
    from ..sim.scene import load_scene
    from ..sim.simulate import Simulation

    output = Path(output)
    values: dict[str, Any] = {"angle": angle, "resolution": resolution, "range_m": range_m, "units": units}
    given = [k for k in LMS_OPTIONS if values[k] is not None]
    loaded = load_scene(scene)
    if loaded.scanner is not None and given:
        names = ", ".join("--" + k.replace("range_m", "range") for k in given)
        raise OptionError(
            f"{loaded.source}: the scene sets its own scanner ([scanner]); {names} "
            f"appl{'ies' if len(given) == 1 else 'y'} to the LMS200"
        )
    if laser_pose is not None and loaded.sensor.mount is not None:
        raise OptionError(
            f"{loaded.source}: the scene mounts its scanner ([sensor] laser_pose); --laser-pose would place it twice"
        )
    fov = int(angle if angle is not None else 180)
    step = float(resolution if resolution is not None else 0.5)
    mode = int(range_m if range_m is not None else 8)
    if units is None:
        units = "cm" if mode == 80 else "mm"
    lms: dict[str, Any] = (
        {}
        if loaded.scanner is not None
        else {"fov_deg": fov, "resolution_deg": step, "range_mode_m": mode, "units": units}
    )
    sim = Simulation(loaded, seed=seed, duration=duration, rate=rate, noise_sigma=noise, people=people, **lms)
    params = {
        "scene": scene,
        "seed": seed,
        "duration": duration if duration is not None else loaded.duration,
        "rate": sim.sensor.rate_hz,
        "people": people,
    }
    if loaded.scanner is None:
        params |= {"angle": fov, "resolution": step, "range": mode, "units": units}
    else:
        sc = loaded.scanner
        params["scanner"] = {"beams": sc.beams, "fov_deg": sc.fov_deg, "range_m": [sc.range_min, sc.range_max]}
    params["noise"] = noise
    if laser_pose is not None:
        params["laser_pose"] = {"x_m": laser_pose[0], "y_m": laser_pose[1], "yaw_deg": math.degrees(laser_pose[2])}
    user_file = scene.endswith(".toml") or "/" in scene
    n, n_objects, geometry = len(sim), len(sim.objects), sim.geometry
    if output.suffix == ".bag":
        with bar("simulating", len(sim)) as done:
            write_simulation_bag(output, sim, laser_pose, force=force, progress=done)
        return SimulateResult(output, n, n_objects, geometry, bag=True)
    if command_line is None:
        command_line = f"datmo_cli.api.simulate({os.fsdecode(output)!r}, {scene!r})"
    provenance = mcapio.Provenance("simulate", params, [scene] if user_file else [], command_line)
    with mcapio.LogWriter(output, force=force, provenance=provenance) as writer:
        with bar("simulating", len(sim)) as done:
            write_simulation(writer, sim, laser_pose, progress=done)
    return SimulateResult(output, n, n_objects, geometry, bag=False)
