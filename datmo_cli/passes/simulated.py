"""The simulator's scenes as inputs of the other core packages, which never import it themselves: exactly
labelled leg recordings for training the leg detector (perception.training), and scans for the LMS200
emulator (lms2xx.emulator).

The simulator knows every leg's centre (GroundTruth left/right leg, sensor frame, metres), so its scans are
exactly labelled. They teach the detector the LMS200's geometry (0.5° and 1° steps, legs of the paper's
10 cm radius at 1-8 m) that the real training bags (a 0.35° Hokuyo within about 5 m) lack. The scenes and
seeds below are never those of sample_logs/ (seed 1), so the sample logs stay held out.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..lms2xx.scan_sources import LogSource, ScanSource
from ..logs.vocabulary import CLASS_PERSON

# ------------------------------------------------------------------------------------ leg recordings

# (scene, seed, people or None, resolution in degrees, duration in s); a resolution that is not the LMS200's
# (0.25, 0.5, 1) is a scanner of 270° with that step (a Hokuyo-like one, its beams = 270 / step), whose crowd
# stands still longer (LONG_PAUSE): people who stand, seen by a scanner finer than the LMS200 and to 8 m
SIMULATED = (
    ("crowd", 11, 6, 0.5, 60.0),
    ("crowd", 12, 8, 1.0, 60.0),
    ("corridor", 13, None, 0.5, 60.0),
    ("crowd", 14, 4, 0.5, 30.0),
    ("crowd", 15, 6, 270 / 768, 60.0),
    ("crowd", 16, 5, 270 / 512, 60.0),
)
LMS200_STEPS = (0.25, 0.5, 1.0)
LONG_PAUSE = (0.5, 12.0)  # pause probability at each waypoint, longest pause in s


def _scene_for(scene: str, resolution: float):
    """The scene to simulate for a SIMULATED row: the built-in name, or the scene loaded with the scanner of
    `resolution` degrees over 270° (and the crowd's LONG_PAUSE) when it is not an LMS200 step."""
    if any(abs(resolution - s) < 1e-9 for s in LMS200_STEPS):
        return scene, resolution
    import dataclasses

    from ..sim.scene import ScannerSpec, load_scene

    loaded = load_scene(scene)
    crowd = loaded.crowd and dataclasses.replace(loaded.crowd, pause_probability=LONG_PAUSE[0], max_pause=LONG_PAUSE[1])
    spec = ScannerSpec(beams=int(round(270 / resolution)), fov_deg=270.0, range_min=0.02, range_max=10.0)
    return dataclasses.replace(loaded, scanner=spec, crowd=crowd), None


def simulated_recording(
    scene: str, seed: int, people: int | None = None, resolution: float = 0.5, duration: float = 60.0
):
    """One simulated recording with every visible person's two leg centres as its labels: an LMS200 at
    `resolution` degrees, or a 270° scanner of that step (_scene_for)."""
    from ..perception.training import Recording
    from ..sim.simulate import simulate_scene

    where, lms_step = _scene_for(scene, resolution)
    sim = simulate_scene(where, seed=seed, duration=duration, people=people, resolution_deg=lms_step)
    legs = []
    for k in range(len(sim.run)):
        o = sim.truth[sim.truth_offsets[k] : sim.truth_offsets[k + 1]]
        o = o[(o["classification"] == CLASS_PERSON) & (o["visible"] == 1)]
        left = np.stack([o["left_leg_x"], o["left_leg_y"]], axis=1)
        right = np.stack([o["right_leg_x"], o["right_leg_y"]], axis=1)
        legs.append(np.concatenate([left, right]).astype(np.float64).reshape(-1, 2))
    name = f"simulated {scene} seed {seed}" + (f" {people} people" if people else "") + f" {resolution:.3g}°"
    return Recording(name, Path(f"simulated/{scene}-{seed}"), "/scan", sim.run, legs)


def simulated_recordings() -> list:
    """The SIMULATED recordings (about 1,000 scans; a second or two to simulate)."""
    return [simulated_recording(*spec) for spec in SIMULATED]


# ------------------------------------------------------------------------------------- emulator scans


class SceneSource(ScanSource):
    """A simulated scene (datmo_cli.sim), regenerated with the same seed when its duration runs out."""

    def __init__(self, scene: str, *, seed: int = 0, duration: float | None = None, noise: float = 0.01) -> None:
        self.scene, self.seed, self.duration, self.noise = scene, seed, duration, noise

    def _simulation(self, angle_deg: int, resolution_cdeg: int, units: str, measuring_mode: int):
        from ..lms2xx.protocol import distance_bits
        from ..sim.sensor import MAX_RATE_HZ
        from ..sim.simulate import Simulation

        bits = distance_bits(measuring_mode)
        range_m = 80 if units == "cm" and bits == 13 else {13: 8, 14: 16, 15: 32, 16: 32}[bits]
        res = resolution_cdeg / 100
        return Simulation(
            self.scene,
            seed=self.seed,
            duration=self.duration,
            rate=MAX_RATE_HZ[res],
            fov_deg=angle_deg,
            resolution_deg=res,
            range_mode_m=range_m,
            units=units,
            noise_sigma=self.noise,
        )

    def scans(self, angle_deg, resolution_cdeg, units, measuring_mode):
        while True:
            sim = self._simulation(angle_deg, resolution_cdeg, units, measuring_mode)
            for chunk in sim.chunks(64):
                yield from chunk.codes


def scan_source(
    *, log: str | Path | None = None, scene: str | None = None, seed: int = 0, duration: float | None = None
) -> ScanSource:
    """A LogSource for `log`, else a SceneSource for `scene` (default: the hall scene); ConfigError for a scene
    with a scanner of its own (the emulator is an LMS200)."""
    if log is not None:
        return LogSource(log)
    from ..base.errors import ConfigError
    from ..sim.scene import load_scene

    loaded = load_scene(scene or "hall")
    if loaded.scanner is not None:
        raise ConfigError(f"{loaded.source}: the scene sets its own scanner ([scanner]); the emulator is an LMS200")
    return SceneSource(scene or "hall", seed=seed, duration=duration)


def write_simulation(
    writer, sim, laser_pose: tuple[float, float, float] | None = None, progress: Callable[[int], None] | None = None
) -> None:
    """Write simulation `sim` (sim.simulate.Simulation) block by block into `writer` (an open mcapio.LogWriter):
    /scan, /odom and /tf for a moving sensor (unless its scene leaves the odometry out), /datmo/ground_truth,
    /tf_static for a log with /odom or a laser pose, and the scene as metadata. `laser_pose` (x m, y m, yaw rad:
    the scanner on the base) defaults to the scene's. Each block is written and forgotten before the next is
    cast, so memory holds one block whatever the duration; `progress` gets the scans written so far after each
    block."""
    from ..logs import mcapio, transforms, types
    from ..logs.scan import Odometry, ScanRun
    from ..sim.simulate import ground_truth_payloads

    scene = sim.scene
    writer.add_metadata("datmo.scene", {"name": scene.name, "source": Path(scene.source).name, "toml": scene.text})
    scan_cid = writer.channel(mcapio.TOPIC_SCAN, types.LASERSCAN)
    odom_cid = writer.channel(mcapio.TOPIC_ODOM, types.ODOMETRY) if sim.writes_odometry else None
    truth_cid = writer.channel(mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH)
    laser_pose = laser_pose if laser_pose is not None else sim.mount
    mount = transforms.LaserPose(*laser_pose) if laser_pose is not None else None
    base, laser = transforms.BASE_FRAME, sim.geometry.frame_id
    if mount is not None:
        writer.add_metadata(transforms.LASER_POSE_RECORD, mount.record(base, laser))
    if mount is not None or odom_cid is not None:
        t0 = int(sim.stamps[0])
        writer.write_transforms(
            [t0], [transforms.mount_tf(t0, base, laser, mount or transforms.LaserPose())], static=True
        )
    for c in sim.chunks():
        run = ScanRun(c.stamps, c.ranges, sim.geometry)
        writer.write_ids(scan_cid, c.stamps, mcapio.encode_scans(run))
        if odom_cid is not None:
            p = c.sensor_poses
            odom = Odometry(c.stamps.copy(), p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())
            if mount is not None:
                odom = transforms.base_odometry(odom, mount, base)
            writer.write_ids(odom_cid, c.stamps, mcapio.encode_odometry(odom))
            writer.write_transforms(c.stamps, transforms.odometry_tf(odom))
        writer.write_ids(
            truth_cid, c.stamps, ground_truth_payloads(c.stamps, c.sensor_poses, c.truth, sim.geometry.frame_id)
        )
        writer.drain()
        if progress is not None:
            progress(c.start + len(c.stamps))


def write_simulation_bag(
    path,
    sim,
    laser_pose: tuple[float, float, float] | None = None,
    *,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
) -> None:
    """Write simulation `sim` as a ROS 1 bag at `path`, as a ROS 1 robot records it: /scan, /odom when the log
    gets odometry (the base's poses, as write_simulation), and /tf holding `/odom -> /base_link` for each pose
    and the mount `/base_link -> /laser` repeated with every scan (the identity when there is odometry but no
    laser pose); frame names slash-prefixed, nothing on /tf_static. `laser_pose` (x m, y m, yaw rad) defaults
    to the scene's. No ground truth: a ROS 1 bag has no datmo_msgs (simulate to MCAP for it). Written block by
    block, like write_simulation."""
    from dataclasses import replace

    from ..logs import transforms
    from ..logs.bag1 import Ros1BagWriter, ros1_frame
    from ..logs.scan import Odometry, ScanRun

    laser_pose = laser_pose if laser_pose is not None else sim.mount
    mount = transforms.LaserPose(*laser_pose) if laser_pose is not None else None
    odom_frame, base, laser = ros1_frame("odom"), ros1_frame(transforms.BASE_FRAME), ros1_frame(sim.geometry.frame_id)
    geometry = replace(sim.geometry, frame_id=laser)
    fixed = mount if mount is not None else transforms.LaserPose() if sim.writes_odometry else None
    with Ros1BagWriter(path, force=force) as bag:
        for c in sim.chunks():
            stamps = c.stamps.tolist()
            if fixed is not None:
                for t in stamps:
                    bag.transforms(t, [transforms.Transform.planar(t, base, laser, fixed.x, fixed.y, fixed.yaw)])
            if sim.writes_odometry:
                p = c.sensor_poses
                odom = Odometry(c.stamps.copy(), p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy(), odom_frame, laser)
                if mount is not None:
                    odom = transforms.base_odometry(odom, mount, base)
                else:
                    odom = Odometry(odom.stamps, odom.x, odom.y, odom.theta, odom_frame, base)
                for t, x, y, th in zip(stamps, odom.x.tolist(), odom.y.tolist(), odom.theta.tolist(), strict=True):
                    bag.transforms(t, [transforms.Transform.planar(t, odom_frame, base, x, y, th)])
                bag.odometry(odom)
            bag.scans(ScanRun(c.stamps, c.ranges, geometry))
            if progress is not None:
                progress(c.start + len(c.stamps))
