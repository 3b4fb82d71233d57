"""Scenes: readable TOML files (built-in ones in `datmo_cli/sim/scenes/`) validated into plain dataclasses.

World frame, metres and seconds; angles in scene files are degrees (keys end in `_deg`), radians here.
Every problem raises ConfigError naming the file and the table and key (or the TOML line).

Scene file format (points are [x, y]; every table is optional; unknown keys are errors):

    name, description, duration (s, default 60), rate (scans per second, default 5; --rate overrides it)
    [sensor]      where the scanner is, one of: pose = [x, y, heading_deg] (a still scanner); a path (a robot
                  driving it, facing its way, with turn_rate_deg = 90: it turns on the spot where the path
                  bends); or follow = "person name" (a robot trailing that walking person along their path,
                  gap = [1.5, 2.5] m behind: it drives at up to `speed` (m/s, default 1.3, above the person's)
                  in proportion to how far the gap exceeds its low end, so it stops behind a person who stops
                  and the gap shrinks to the low end and holds; it faces the person).
                  odometry = true: a moving scanner's log gets /odom (and /tf); false leaves them out (the
                  robot's motion is then unknown to datmo, which estimates it by scan matching).
                  laser_pose = [x, y, yaw_deg]: the scanner's mount on the robot (m, m, degrees in base_link);
                  pose, path or follow then place the robot's base, the scanner sits at base + mount, and the
                  log gets the mount on /tf_static and in `datmo.laser_pose` (as --laser-pose does).
    [scanner]     a scanner other than the LMS200 (the default, set by --angle, --resolution, --range):
                  beams, fov_deg (beams fov/beams apart from -fov/2), range = [min, max] (m); e.g. a Hokuyo
                  like the leg_tracker bags': beams = 768, fov_deg = 270.0, range = [0.02, 10.0]
    [[wall]]      points = [[x, y], ...], closed = false
    [[column]]    center, radius
    [[bench]]     supports = [[x, y], [x, y]], support_radius = 0.1, seat_width = 0.35 (0: no seat)
    [[box]]       size = [length, width], and center + orientation_deg (static) or a path (moving)
    [[platform]]  radius = 0.25, and center (static), a path (driven) or pulled_by = "person name"
                  with wire = 2.0 (towed; starts `wire` behind the person, or at center)
    [[person]]    name, a path (walking) or position + heading_deg (standing), and the gait:
                  shoulder_width = 0.3, leg_radius = 0.1, leg_length = 0.9, swing_angle_deg = 22,
                  step_length (instead of 2 l sin(theta)), double_support = 0.15
    [crowd]       people = 6, area = [[x0, y0], [x1, y1]], speed = [0.8, 1.4], pause_probability = 0.2,
                  max_pause = 3.0

A path is: path = [[x, y], ...] (two or more waypoints), speed (m/s, default 1), loop = false,
start_time (s), pauses = [[waypoint index, seconds], ...].

Ground-truth ids follow the table order: people first, in file order (so the first [[person]] is id 1),
then the crowd, moving platforms and boxes, static fixtures, wall corners and wall segments (sim/world.py).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ..base import toml_text
from ..base.bounds import OPTIONS
from ..base.errors import ConfigError, InputError
from .paths import PathSpec
from .scene_fields import PATH_KEYS, SceneValidator
from .walking import Gait

GAIT_KEYS = {"shoulder_width", "leg_radius", "leg_length", "swing_angle_deg", "step_length", "double_support"}


@dataclass(frozen=True)
class Wall:
    points: np.ndarray  # (K, 2) polyline vertices
    closed: bool = False


@dataclass(frozen=True)
class Column:
    center: np.ndarray
    radius: float


@dataclass(frozen=True)
class Bench:
    """Two circular supports with a rectangular seat between their centres."""

    supports: np.ndarray  # (2, 2)
    support_radius: float = 0.1
    seat_width: float = 0.35


@dataclass(frozen=True)
class Box:
    """A rectangle (box, robot): `length` along its heading; static at `center` or moving along `path`."""

    length: float
    width: float
    center: np.ndarray | None = None
    orientation: float = 0.0
    path: PathSpec | None = None


@dataclass(frozen=True)
class Platform:
    """A circular mobile platform: static, driven along a path, or pulled by a person on a wire."""

    radius: float
    center: np.ndarray | None = None
    path: PathSpec | None = None
    pulled_by: str | None = None
    wire: float = 2.0


@dataclass(frozen=True)
class Person:
    name: str
    gait: Gait
    path: PathSpec | None = None
    position: np.ndarray | None = None  # standing still when there is no path
    heading: float = 0.0


@dataclass(frozen=True)
class Crowd:
    """`people` walkers on random waypoint paths inside `area` ((x0, y0), (x1, y1))."""

    people: int
    area: np.ndarray
    speed: tuple[float, float] = (0.8, 1.4)
    pause_probability: float = 0.2
    max_pause: float = 3.0


@dataclass(frozen=True)
class SensorPlacement:
    """A still scanner at `pose` (x, y in m, heading in rad), one driving along `path`, facing its way and
    turning on the spot at `turn_rate` (rad/s) where the path bends, or one following the person named
    `follow` `gap` (low, high; m) behind along their path at up to `follow_speed` m/s. `odometry`: whether a
    moving scanner's log gets /odom. `mount`: the scanner on the robot (x, y in m, yaw in rad, base frame); the
    placement is then the base's."""

    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    path: PathSpec | None = None
    turn_rate: float = float(np.pi / 2)
    follow: str | None = None
    gap: tuple[float, float] = (1.5, 2.5)
    follow_speed: float = 1.3
    odometry: bool = True
    mount: np.ndarray | None = None


@dataclass(frozen=True)
class ScannerSpec:
    """A [scanner] table: `beams` beams over `fov_deg` degrees (fov/beams apart from -fov/2), ranges from
    `range_min` to `range_max` m."""

    beams: int
    fov_deg: float
    range_min: float
    range_max: float


@dataclass(frozen=True)
class Scene:
    name: str
    source: str
    text: str
    description: str = ""
    duration: float = 60.0
    rate: float | None = None
    scanner: ScannerSpec | None = None
    sensor: SensorPlacement = field(default_factory=SensorPlacement)
    walls: tuple[Wall, ...] = ()
    columns: tuple[Column, ...] = ()
    benches: tuple[Bench, ...] = ()
    boxes: tuple[Box, ...] = ()
    platforms: tuple[Platform, ...] = ()
    people: tuple[Person, ...] = ()
    crowd: Crowd | None = None


def builtin_scenes() -> dict[str, str]:
    """Name -> first description line of every shipped scene."""
    out = {}
    for entry in sorted((resources.files("datmo_cli.sim") / "scenes").iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            lines = str(tomllib.loads(entry.read_text(encoding="utf-8")).get("description", "")).strip().splitlines()
            out[entry.name[:-5]] = lines[0] if lines else ""
    return out


def load_scene(scene: str | Path) -> Scene:
    """A built-in scene by name, or a scene file (a Path, or a name ending in .toml or holding a "/")."""
    text_path = str(scene)
    if isinstance(scene, Path) or text_path.endswith(".toml") or "/" in text_path:
        from ..base.input_files import check

        path = Path(scene)
        if not path.exists():
            raise InputError(f"{path}: scene file not found")
        check(path)  # a folder, FIFO or device: one line saying what it is
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: cannot read the scene file ({exc})") from None
        return parse_scene(text, str(path), default_name=path.stem)
    names = builtin_scenes()
    if text_path not in names:
        raise ConfigError(
            f"unknown scene '{text_path}' (built-in: {', '.join(names)}; or give the path of a .toml scene file)"
        )
    text = (resources.files("datmo_cli.sim") / "scenes" / f"{text_path}.toml").read_text(encoding="utf-8")
    return parse_scene(text, f"{text_path}.toml", default_name=text_path)


def parse_scene(text: str, source: str = "<scene>", default_name: str = "scene") -> Scene:
    """Validate TOML text into a Scene; `source` names the file in error messages."""
    data = toml_text.loads(text, source, "invalid TOML: ")  # a BOM read, huge numbers and deep nesting refused
    v = SceneValidator(source)
    v.keys(
        data,
        "top level",
        {
            "name",
            "description",
            "duration",
            "rate",
            "sensor",
            "scanner",
            "wall",
            "column",
            "bench",
            "box",
            "platform",
            "person",
            "crowd",
        },
    )
    kw: dict = {
        "name": v.string(data, "top level", "name", default_name),
        "description": v.string(data, "top level", "description", ""),
        "duration": v.bounded(data, "top level", "duration", 60.0, OPTIONS["sim_duration"]),
    }
    if "rate" in data:
        kw["rate"] = v.bounded(data, "top level", "rate", 5.0, OPTIONS["sim_rate"])
    if "scanner" in data:
        kw["scanner"] = _scanner(v, v.table(data, "scanner", "[scanner]"))
    if "sensor" in data:
        kw["sensor"] = _sensor(v, v.table(data, "sensor", "[sensor]"))
    kw["walls"] = tuple(_wall(v, t, w) for t, w in v.tables(data, "wall"))
    kw["columns"] = tuple(_column(v, t, w) for t, w in v.tables(data, "column"))
    kw["benches"] = tuple(_bench(v, t, w) for t, w in v.tables(data, "bench"))
    kw["boxes"] = tuple(_box(v, t, w) for t, w in v.tables(data, "box"))
    kw["people"] = tuple(_person(v, t, w, i) for i, (t, w) in enumerate(v.tables(data, "person"), 1))
    kw["platforms"] = tuple(_platform(v, t, w) for t, w in v.tables(data, "platform"))
    names = [p.name for p in kw["people"]]
    for i, (_, w) in enumerate(v.tables(data, "platform")):
        pulled = kw["platforms"][i].pulled_by
        if pulled is not None and pulled not in names:
            raise ConfigError(f"{source}: {w}, key 'pulled_by': no person is named '{pulled}'")
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ConfigError(f"{source}: [[person]] names must be unique; '{sorted(dup)[0]}' is used twice")
    if "crowd" in data:
        kw["crowd"] = _crowd(v, v.table(data, "crowd", "[crowd]"))
    _check_follow(v, kw.get("sensor"), kw["people"])
    return Scene(source=source, text=text, **kw)


def _sensor(v: SceneValidator, t: dict) -> SensorPlacement:
    where = "[sensor]"
    v.keys(t, where, {"pose", "turn_rate_deg", "follow", "gap", "odometry", "laser_pose"} | PATH_KEYS)
    placements = [k for k in ("pose", "path", "follow") if k in t]
    if len(placements) > 1:
        raise ConfigError(
            f"{v.source}: {where}: give 'pose' (a still scanner), 'path' (a moving one) or 'follow' "
            f"(one trailing a person), not both {' and '.join(repr(k) for k in placements)}"
        )
    mount = v.vector(t, where, "laser_pose", 3, default=None)
    if mount is not None:
        mount[2] = np.radians(mount[2])
    odometry = v.boolean(t, where, "odometry", True)
    if "follow" in t:
        for k in PATH_KEYS - {"speed"} | {"turn_rate_deg"}:
            if k in t:
                v.fail(where, k, "does not apply to a scanner that follows a person")
        gap = v.vector(t, where, "gap", 2, default=[1.5, 2.5])
        if not 0 < gap[0] < gap[1]:
            v.fail(where, "gap", f"give [low, high] with 0 < low < high, got {gap.tolist()}")
        return SensorPlacement(
            follow=v.string(t, where, "follow"),
            gap=(float(gap[0]), float(gap[1])),
            follow_speed=v.number(t, where, "speed", 1.3, positive=True),
            odometry=odometry,
            mount=mount,
        )
    if "gap" in t:
        v.fail(where, "gap", "only applies with 'follow'")
    pose = v.vector(t, where, "pose", 3, default=[0.0, 0.0, 0.0])
    pose[2] = np.radians(pose[2])
    turn = np.radians(v.number(t, where, "turn_rate_deg", 90.0, positive=True))
    return SensorPlacement(
        pose=pose, path=v.path(t, where, required=False), turn_rate=float(turn), odometry=odometry, mount=mount
    )


def _check_follow(v: SceneValidator, sensor: SensorPlacement | None, people: tuple[Person, ...]) -> None:
    """A followed person exists, walks, and is slower than the robot."""
    if sensor is None or sensor.follow is None:
        return
    leader = {p.name: p for p in people}.get(sensor.follow)
    if leader is None:
        v.fail("[sensor]", "follow", f"no [[person]] is named '{sensor.follow}'")
    if leader.path is None:
        v.fail("[sensor]", "follow", f"'{sensor.follow}' stands still (give them a path)")
    if leader.path.speed >= sensor.follow_speed:
        v.fail(
            "[sensor]",
            "speed",
            f"the robot's top speed {sensor.follow_speed:g} m/s must be above "
            f"'{sensor.follow}''s {leader.path.speed:g} m/s, or it falls behind",
        )


def _scanner(v: SceneValidator, t: dict) -> ScannerSpec:
    where = "[scanner]"
    v.keys(t, where, {"beams", "fov_deg", "range"})
    beams = v.integer(t, where, "beams")
    fov = v.number(t, where, "fov_deg", positive=True)
    rng = v.vector(t, where, "range", 2)
    if not 2 <= beams <= 10_000:
        v.fail(where, "beams", f"must be 2 to 10000, got {beams}")
    if fov > 360:
        v.fail(where, "fov_deg", f"must be at most 360, got {fov:g}")
    if not 0 <= rng[0] < rng[1] <= 60:
        v.fail(where, "range", f"give [min, max] with 0 <= min < max <= 60 m, got {rng.tolist()}")
    return ScannerSpec(beams, fov, float(rng[0]), float(rng[1]))


def _wall(v: SceneValidator, t: dict, where: str) -> Wall:
    v.keys(t, where, {"points", "closed"})
    pts = v.points(t, where, "points", minimum=2)
    closed = v.boolean(t, where, "closed", False)
    if closed and len(pts) < 3:
        raise ConfigError(f"{v.source}: {where}, key 'points': a closed wall needs 3 or more points")
    if np.any(np.all(np.diff(np.vstack([pts, pts[:1]]) if closed else pts, axis=0) == 0, axis=1)):
        raise ConfigError(f"{v.source}: {where}, key 'points': two consecutive points are equal")
    return Wall(pts, closed)


def _column(v: SceneValidator, t: dict, where: str) -> Column:
    v.keys(t, where, {"center", "radius"})
    return Column(v.vector(t, where, "center", 2), v.number(t, where, "radius", positive=True))


def _bench(v: SceneValidator, t: dict, where: str) -> Bench:
    v.keys(t, where, {"supports", "support_radius", "seat_width"})
    sup = v.points(t, where, "supports", minimum=2)
    if len(sup) != 2 or np.all(sup[0] == sup[1]):
        raise ConfigError(f"{v.source}: {where}, key 'supports': give two different points")
    return Bench(
        sup,
        v.number(t, where, "support_radius", 0.1, positive=True),
        v.number(t, where, "seat_width", 0.35, nonnegative=True),
    )


def _box(v: SceneValidator, t: dict, where: str) -> Box:
    v.keys(t, where, {"center", "size", "orientation_deg"} | PATH_KEYS)
    size = v.vector(t, where, "size", 2)
    if np.any(size <= 0):
        raise ConfigError(f"{v.source}: {where}, key 'size': length and width must be > 0")
    path = v.path(t, where, required=False)
    center = v.vector(t, where, "center", 2, default=None)
    if (path is None) == (center is None):
        raise ConfigError(f"{v.source}: {where}: give either 'center' (static) or 'path' (moving)")
    return Box(
        float(size[0]), float(size[1]), center, float(np.radians(v.number(t, where, "orientation_deg", 0.0))), path
    )


def _platform(v: SceneValidator, t: dict, where: str) -> Platform:
    v.keys(t, where, {"radius", "center", "pulled_by", "wire"} | PATH_KEYS)
    radius = v.number(t, where, "radius", 0.25, positive=True)
    path = v.path(t, where, required=False)
    pulled = v.string(t, where, "pulled_by", None)
    center = v.vector(t, where, "center", 2, default=None)
    if sum(x is not None for x in (path, pulled)) > 1 or (center is None and path is None and pulled is None):
        raise ConfigError(
            f"{v.source}: {where}: give 'center' (static), 'path' (driven) or "
            "'pulled_by' (towed, starting at 'center' if given)"
        )
    if path is not None and center is not None:
        raise ConfigError(f"{v.source}: {where}: a driven platform starts at its path's first point; drop 'center'")
    return Platform(radius, center, path, pulled, v.number(t, where, "wire", 2.0, positive=True))


def _person(v: SceneValidator, t: dict, where: str, index: int) -> Person:
    v.keys(t, where, {"name", "position", "heading_deg"} | PATH_KEYS | GAIT_KEYS)
    g = Gait()
    step = v.number(t, where, "step_length", None, positive=True)
    gait = Gait(
        leg_length=v.number(t, where, "leg_length", g.leg_length, positive=True),
        swing_angle=float(np.radians(v.number(t, where, "swing_angle_deg", np.degrees(g.swing_angle), positive=True))),
        shoulder_width=v.number(t, where, "shoulder_width", g.shoulder_width, positive=True),
        leg_radius=v.number(t, where, "leg_radius", g.leg_radius, positive=True),
        double_support=v.number(t, where, "double_support", g.double_support, nonnegative=True),
        step=step,
    )
    if gait.double_support >= 1:
        raise ConfigError(f"{v.source}: {where}, key 'double_support': must be below 1")
    if gait.step_length <= 0:
        raise ConfigError(f"{v.source}: {where}: the step length 2 l sin(theta) must be > 0")
    path = v.path(t, where, required=False)
    position = v.vector(t, where, "position", 2, default=None)
    if (path is None) == (position is None):
        raise ConfigError(f"{v.source}: {where}: give either 'path' (walking) or 'position' (standing)")
    return Person(
        v.string(t, where, "name", f"person{index}"),
        gait,
        path,
        position,
        float(np.radians(v.number(t, where, "heading_deg", 0.0))),
    )


def _crowd(v: SceneValidator, t: dict) -> Crowd:
    where = "[crowd]"
    v.keys(t, where, {"people", "area", "speed", "pause_probability", "max_pause"})
    people = v.bounded(t, where, "people", 6, OPTIONS["people"])
    area = v.points(t, where, "area", minimum=2)
    if len(area) != 2 or np.any(area[1] <= area[0]):
        raise ConfigError(f"{v.source}: {where}, key 'area': give [[x0, y0], [x1, y1]] with x0 < x1 and y0 < y1")
    speed = v.vector(t, where, "speed", 2, default=[0.8, 1.4])
    if not 0 < speed[0] <= speed[1]:
        raise ConfigError(f"{v.source}: {where}, key 'speed': give [low, high] with 0 < low <= high")
    prob = v.number(t, where, "pause_probability", 0.2, nonnegative=True)
    if prob > 1:
        raise ConfigError(f"{v.source}: {where}, key 'pause_probability': must be in [0, 1]")
    return Crowd(
        int(people),
        area,
        (float(speed[0]), float(speed[1])),
        prob,
        v.number(t, where, "max_pause", 3.0, nonnegative=True),
    )
