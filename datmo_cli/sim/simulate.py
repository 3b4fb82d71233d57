"""Run a scene: scans as an LMS200 would send them, the sensor's poses, and ground truth for every scan.

The public entry point is `simulate_scene`. Scans are in the sensor frame "laser" (x forward, y left,
beams counter-clockwise from -fov/2); poses and ground-truth world coordinates are in the world frame,
which is also the odometry frame "odom". Deterministic for a seed: the scene's random parts (crowds)
and the range noise draw from separate streams of one numpy SeedSequence, and stamps start at a fixed
epoch, never the wall clock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from datmo_cli.base import libm

from ..base.bounds import OPTIONS, check
from ..base.errors import ConfigError
from ..logs import cdr, types
from ..logs.scan import Odometry, ScanRun
from .raycast import cast
from .scene import Scene, load_scene
from .sensor import Scanner, Sensor
from .world import ObjectInfo, World

START_NS = 1_088_985_600 * 1_000_000_000  # 2004-07-05T00:00:00Z, the first scan's stamp
CHUNK = 512  # scans cast per kernel call
CORNER_RADIUS = 0.3  # m: beams on a corner's walls this close to it count as hits
MOVING_SPEED = 0.01  # m/s


@dataclass
class SimResult:
    """A simulated run.

    truth: ground-truth objects of every scan, one flat structured array of
    `cdr.element_dtype(types.GROUND_TRUTH_OBJECT)`; scan k's objects are truth[truth_offsets[k]:truth_offsets[k + 1]].
    sensor_poses (N, 3): x, y (m), heading (rad) of the scanner in the world frame at each scan. codes (N, B)
    uint16: the values the scanner would send (see sensor.Sensor.measure, sensor.Scanner.measure); run.ranges are
    their ranges. odometry: the scanner's poses when the log gets /odom (a moving scanner whose scene does not
    leave them out), else None.
    """

    run: ScanRun
    odometry: Odometry | None
    truth: np.ndarray
    truth_offsets: np.ndarray
    sensor_poses: np.ndarray
    codes: np.ndarray
    sensor: Sensor | Scanner
    scene: Scene
    objects: list[ObjectInfo]

    def truth_at(self, k: int) -> np.ndarray:
        """Ground-truth objects of scan k."""
        return self.truth[self.truth_offsets[k] : self.truth_offsets[k + 1]]

    def ground_truth_payloads(self) -> list[bytes]:
        """CDR payloads of datmo_msgs/msg/GroundTruth, one per scan, stamped like the scans."""
        truth = self.truth.reshape(len(self.run), -1)
        return ground_truth_payloads(self.run.stamps, self.sensor_poses, truth, self.run.geometry.frame_id)


def ground_truth_payloads(
    stamps: np.ndarray, sensor_poses: np.ndarray, truth: np.ndarray, frame_id: str
) -> list[bytes]:
    """CDR payloads of datmo_msgs/msg/GroundTruth of scans with these stamps, sensor poses (n, 3) and
    ground-truth records (n, n_objects), as SimResult and SimChunk hold them."""
    return [
        cdr.encode(
            types.GROUND_TRUTH,
            {
                "stamp_ns": int(s),
                "frame_id": frame_id,
                "sensor_x": float(p[0]),
                "sensor_y": float(p[1]),
                "sensor_theta": float(p[2]),
                "objects": truth[k],
            },
        )
        for k, (s, p) in enumerate(zip(stamps, sensor_poses, strict=True))
    ]


@dataclass
class SimChunk:
    """Consecutive scans `start`..`start + len(stamps) - 1` of a Simulation (see SimResult for the fields)."""

    start: int
    stamps: np.ndarray  # (n,) int64 ns
    sensor_poses: np.ndarray  # (n, 3)
    codes: np.ndarray  # (n, B) uint16
    ranges: np.ndarray  # (n, B) float32
    truth: np.ndarray  # (n, n_objects) ground-truth records


class Simulation:
    """A run prepared but not yet cast: scans are produced block by block by `chunks()`, in one pass.

    For streaming consumers (`datmo simulate`, which writes each block as it comes, and the LMS emulator);
    `simulate_scene` collects the whole run. Arguments as for `simulate_scene`. The world model (paths,
    crowds) is laid out for the whole duration up front; the scans and ground truth come block by block.
    """

    def __init__(
        self,
        scene: str | Path | Scene,
        *,
        seed: int = 0,
        duration: float | None = None,
        rate: float | None = None,
        fov_deg: int | None = None,
        resolution_deg: float | None = None,
        range_mode_m: int | None = None,
        units: str | None = None,
        noise_sigma: float = 0.01,
        people: int | None = None,
        dropout: float = 0.0,
    ) -> None:
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        rate = rate if rate is not None else self.scene.rate if self.scene.rate is not None else 5.0
        lms = {"fov_deg": fov_deg, "resolution_deg": resolution_deg, "range_mode_m": range_mode_m, "units": units}
        spec = self.scene.scanner
        self.sensor: Sensor | Scanner
        try:
            if spec is not None:
                given = [k for k, x in lms.items() if x is not None]
                if given:
                    raise ConfigError(
                        f"{self.scene.source}: the scene sets its own scanner ([scanner]); "
                        f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to the LMS200"
                    )
                self.sensor = Scanner(
                    spec.beams,
                    spec.fov_deg,
                    spec.range_min,
                    spec.range_max,
                    float(noise_sigma),
                    float(rate),
                    float(dropout),
                )
            else:
                self.sensor = Sensor(
                    180 if fov_deg is None else int(fov_deg),
                    0.5 if resolution_deg is None else float(resolution_deg),
                    8 if range_mode_m is None else int(range_mode_m),
                    units or "mm",
                    float(noise_sigma),
                    float(rate),
                    float(dropout),
                )
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        if duration is not None:
            duration = check(OPTIONS["sim_duration"], float(duration), "duration")
        duration = self.scene.duration if duration is None else duration
        if people is not None and self.scene.crowd is None:
            raise ConfigError(
                f"{self.scene.source}: --people applies to scenes with a [crowd] table; this one has none"
            )
        if people is not None:
            check(OPTIONS["people"], people, "people")
        if seed < 0:
            raise ConfigError(f"seed must be >= 0, got {seed}")
        n = max(1, int(np.floor(duration * self.sensor.rate_hz + 1e-9)))
        self.times = np.arange(n) / self.sensor.rate_hz
        self.stamps = START_NS + np.round(np.arange(n) * (1e9 / self.sensor.rate_hz)).astype(np.int64)
        scene_seed, noise_seed = np.random.SeedSequence(seed).spawn(2)
        self.world = World(self.scene, float(self.times[-1]), scene_seed, people)
        self._noise = np.random.default_rng(noise_seed)
        self._used = False
        self.geometry = self.sensor.geometry("laser")
        self.truth_dtype = cdr.element_dtype(types.GROUND_TRUTH_OBJECT)

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def objects(self) -> list[ObjectInfo]:
        return self.world.objects

    @property
    def sensor_moves(self) -> bool:
        return self.world.sensor.moves

    @property
    def writes_odometry(self) -> bool:
        """Whether the log gets /odom: the scanner moves and the scene does not leave its odometry out."""
        return self.world.sensor.moves and self.scene.sensor.odometry

    @property
    def mount(self) -> tuple[float, float, float] | None:
        """The scene's laser pose on the robot (x m, y m, yaw rad), or None."""
        m = self.scene.sensor.mount
        return None if m is None else (float(m[0]), float(m[1]), float(m[2]))

    def chunks(self, size: int = CHUNK) -> Iterator[SimChunk]:
        """Blocks of `size` scans in time order (the range noise is one stream, so only one pass)."""
        if self._used:
            raise RuntimeError("a Simulation produces its scans once; make a new one")
        self._used = True
        angles = self.sensor.angles()
        for a in range(0, len(self), size):
            b = min(len(self), a + size)
            poses, codes, ranges, truth = _chunk(
                self.world, self.sensor, angles, self.times[a:b], self._noise, self.truth_dtype
            )
            yield SimChunk(a, self.stamps[a:b], poses, codes, ranges, truth)


def simulate_scene(
    scene: str | Path | Scene,
    *,
    seed: int = 0,
    duration: float | None = None,
    rate: float | None = None,
    fov_deg: int | None = None,
    resolution_deg: float | None = None,
    range_mode_m: int | None = None,
    units: str | None = None,
    noise_sigma: float = 0.01,
    people: int | None = None,
    dropout: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
) -> SimResult:
    """Simulate a scanner in `scene` (a built-in name, a .toml path, or a loaded Scene): the scene's [scanner],
    else an LMS200.

    duration (s) defaults to the scene's; rate in Hz (default: the scene's, else 5); the LMS200's field of view
    and resolution in degrees, range mode in metres, units "mm" or "cm" (defaults 180, 0.5, 8, mm; refused for a
    scene with its own [scanner]); noise_sigma: Gaussian range noise, m; people: walkers in the scene's
    crowd (crowd scenes only); dropout: probability that a beam returns nothing (NaN).
    `progress(done, total)` is called after each block of scans. Raises ConfigError on bad settings.
    """
    sim = Simulation(
        scene,
        seed=seed,
        duration=duration,
        rate=rate,
        fov_deg=fov_deg,
        resolution_deg=resolution_deg,
        range_mode_m=range_mode_m,
        units=units,
        noise_sigma=noise_sigma,
        people=people,
        dropout=dropout,
    )
    n, n_obj = len(sim), len(sim.objects)
    truth = np.zeros((n, n_obj), sim.truth_dtype)
    codes = np.empty((n, sim.sensor.n_beams), np.uint16)
    ranges = np.empty((n, sim.sensor.n_beams), np.float32)
    poses = np.empty((n, 3))
    for c in sim.chunks():
        k = slice(c.start, c.start + len(c.stamps))
        poses[k], codes[k], ranges[k], truth[k] = c.sensor_poses, c.codes, c.ranges, c.truth
        if progress is not None:
            progress(k.stop, n)
    stamps = sim.stamps
    run = ScanRun(stamps, ranges, sim.geometry)
    odom = (
        Odometry(stamps.copy(), poses[:, 0].copy(), poses[:, 1].copy(), poses[:, 2].copy())
        if sim.writes_odometry
        else None
    )
    return SimResult(
        run,
        odom,
        truth.reshape(-1),
        np.arange(n + 1, dtype=np.int64) * n_obj,
        poses,
        codes,
        sim.sensor,
        sim.scene,
        sim.objects,
    )


def _chunk(
    world: World,
    sensor: Sensor | Scanner,
    angles: np.ndarray,
    t: np.ndarray,
    noise: np.random.Generator,
    dtype: np.dtype,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(sensor poses, sensor codes, ranges, ground truth (n, n_objects)) of the scans at times t."""
    poses = world.sensor.poses(t)
    states = [(k, m.state(t)) for k, m in world.movers]
    circ = [(s.circles, np.full(s.circles.shape[1], k)) for k, s in states if s.circles is not None]
    segs = [(s.segments, np.full(s.segments.shape[1], k)) for k, s in states if s.segments is not None]
    dist, owner = cast(
        poses,
        angles,
        world.static,
        np.concatenate([a for a, _ in segs], 1) if segs else None,
        np.concatenate([o for _, o in segs]) if segs else None,
        np.concatenate([a for a, _ in circ], 1) if circ else None,
        np.concatenate([o for _, o in circ]) if circ else None,
    )
    codes = sensor.measure(dist, noise)
    ranges = sensor.ranges(codes)
    hits = _hits(world, poses, angles, dist, owner, np.isfinite(ranges) & (owner >= 0))
    return poses, codes, ranges, _truth(world, t, poses, states, hits, dtype)


def _hits(
    world: World, poses: np.ndarray, angles: np.ndarray, dist: np.ndarray, owner: np.ndarray, valid: np.ndarray
) -> np.ndarray:
    """(n, n_objects) beams that hit each object and return a finite range; for wall corners, those on
    either wall within CORNER_RADIUS of the vertex."""
    nb, n_obj = len(poses), len(world.objects)
    rows = np.repeat(np.arange(nb), len(angles)).reshape(nb, -1)
    hits = np.bincount((rows * n_obj + owner)[valid], minlength=nb * n_obj).reshape(nb, n_obj)
    if world.corner_walls:
        beam = poses[:, 2:3] + angles[None, :]
        with np.errstate(invalid="ignore"):
            hx = poses[:, 0:1] + dist * libm.cos(beam)
            hy = poses[:, 1:2] + dist * libm.sin(beam)
        for k, s1, s2 in world.corner_walls:
            cx, cy = world.objects[k].world_xy
            near = valid & ((owner == s1) | (owner == s2)) & (np.hypot(hx - cx, hy - cy) < CORNER_RADIUS)
            hits[:, k] = near.sum(1)
    return hits


def _truth(
    world: World, t: np.ndarray, poses: np.ndarray, states: list, hits: np.ndarray, dtype: np.dtype
) -> np.ndarray:
    """Ground-truth records (n, n_objects): static objects from the table, movers from their states."""
    nb, n_obj = hits.shape
    sensor_vel = world.sensor.velocity(t)
    gt = np.zeros((nb, n_obj), dtype)
    info = world.objects
    wxy = np.tile(np.array([o.world_xy for o in info], np.float64).reshape(1, n_obj, 2), (nb, 1, 1))
    wvel = np.zeros((nb, n_obj, 2))
    orient = np.tile(np.array([o.orientation for o in info]), (nb, 1))
    length = np.tile(np.array([o.length for o in info]), (nb, 1))
    width = np.tile(np.array([o.width for o in info]), (nb, 1))
    gt["left_leg_x"] = gt["left_leg_y"] = gt["right_leg_x"] = gt["right_leg_y"] = np.nan
    c, s = libm.cos(poses[:, 2])[:, None], libm.sin(poses[:, 2])[:, None]

    def to_sensor(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rx, ry = xy[..., 0] - poses[:, 0:1], xy[..., 1] - poses[:, 1:2]
        return c * rx + s * ry, -s * rx + c * ry

    for k, st in states:
        wxy[:, k] = st.xy
        wvel[:, k] = st.velocity
        orient[:, k] = st.heading
        length[:, k] = st.length
        width[:, k] = st.width
        if st.legs is not None:
            for side, leg in zip(("left", "right"), st.legs, strict=True):
                lx, ly = to_sensor(leg[:, None, :])
                gt[f"{side}_leg_x"][:, k] = lx[:, 0]
                gt[f"{side}_leg_y"][:, k] = ly[:, 0]
    gt["id"] = np.arange(1, n_obj + 1)
    gt["classification"] = [o.classification for o in info]
    gt["n_beams"] = hits
    gt["visible"] = hits > 0
    gt["world_x"], gt["world_y"] = wxy[..., 0], wxy[..., 1]
    gt["world_vx"], gt["world_vy"] = wvel[..., 0], wvel[..., 1]
    xs, ys = to_sensor(wxy)
    gt["x"], gt["y"] = xs, ys
    # d/dt of R(-theta)(p - s): the relative velocity turned into the sensor frame, plus the sensor's turning
    rel = wvel - sensor_vel[:, None, :]
    omega = world.sensor.yaw_rate(t)[:, None]
    gt["vx"] = c * rel[..., 0] + s * rel[..., 1] + omega * ys
    gt["vy"] = -s * rel[..., 0] + c * rel[..., 1] - omega * xs
    gt["orientation"] = libm.arctan2(libm.sin(orient), libm.cos(orient))
    gt["length"], gt["width"] = length, width
    gt["moving"] = np.hypot(wvel[..., 0], wvel[..., 1]) > MOVING_SPEED
    return gt
