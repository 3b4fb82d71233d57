"""A scene made concrete: static geometry, movers as functions of time, the sensor's trajectory, and the
table of ground-truth objects. World frame, metres, seconds, radians."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from datmo_cli.base import libm

from ..logs.vocabulary import (
    CLASS_BENCH,
    CLASS_CIRCLE_OBJECT,
    CLASS_COLUMN,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_WALL,
    CLASS_WALL_CORNER,
)
from .paths import PathSpec, Timeline
from .raycast import Primitives, rectangle_segments
from .scene import Crowd, Person, Scene
from .walking import Gait, legs

CORNER_MIN_TURN = np.radians(10.0)  # a polyline vertex is a corner when the wall turns by more than this
TOW_DT = 0.01  # s, integration step of towed loads


@dataclass
class ObjectInfo:
    """One ground-truth object: its index in the table is id - 1. Static ones carry their pose."""

    id: int
    classification: int
    name: str
    world_xy: tuple[float, float] = (np.nan, np.nan)
    orientation: float = 0.0
    length: float = 0.0
    width: float = 0.0


@dataclass
class MoverState:
    """A mover at n instants: centre, velocity (world), heading, size, and its geometry."""

    xy: np.ndarray  # (n, 2)
    velocity: np.ndarray  # (n, 2)
    heading: np.ndarray  # (n,)
    length: np.ndarray  # (n,)
    width: np.ndarray  # (n,)
    circles: np.ndarray | None = None  # (n, c, 3)
    segments: np.ndarray | None = None  # (n, s, 4)
    legs: tuple[np.ndarray, np.ndarray] | None = None


class Walker:
    """A person: two leg circles following the walking model, or standing still."""

    def __init__(self, person: Person, t_end: float) -> None:
        self.gait = person.gait
        self.timeline = Timeline(person.path, t_end) if person.path is not None else None
        self.position = person.position
        self.standing_heading = person.heading

    def body(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.timeline is None:
            n = len(t)
            assert self.position is not None  # a person without a path stands at a position
            return (np.repeat(self.position[None], n, 0), np.zeros((n, 2)), np.full(n, self.standing_heading))
        return self.timeline.position(t), self.timeline.velocity(t), self.timeline.heading(t)

    def state(self, t: np.ndarray) -> MoverState:
        xy, vel, heading = self.body(t)
        g = self.gait
        if self.timeline is None:
            normal = np.stack([-libm.sin(heading), libm.cos(heading)], 1) * (g.shoulder_width / 2)
            left, right = xy + normal, xy - normal
        else:
            left, right = legs(self.timeline, g, t)
        h = np.stack([libm.cos(heading), libm.sin(heading)], 1)
        along = np.abs(np.sum((left - right) * h, 1))
        across = np.abs(np.sum((left - right) * h[:, ::-1] * [-1, 1], 1))
        r = np.full((len(t), 1), g.leg_radius)
        circles = np.stack([np.hstack([left, r]), np.hstack([right, r])], 1)
        return MoverState(
            xy, vel, heading, along + 2 * g.leg_radius, across + 2 * g.leg_radius, circles=circles, legs=(left, right)
        )


class Driven:
    """A circle (platform) or rectangle (box, robot) moving along its own path; the rectangle faces its way."""

    def __init__(
        self, path: PathSpec, t_end: float, radius: float | None = None, size: tuple[float, float] | None = None
    ) -> None:
        self.timeline = Timeline(path, t_end)
        self.radius = radius
        self.size = size

    def state(self, t: np.ndarray) -> MoverState:
        tl = self.timeline
        xy, vel, heading = tl.position(t), tl.velocity(t), tl.heading(t)
        n = len(t)
        if self.radius is not None:
            d = np.full(n, 2 * self.radius)
            circles = np.hstack([xy, np.full((n, 1), self.radius)])[:, None, :]
            return MoverState(xy, vel, heading, d, d, circles=circles)
        assert self.size is not None  # a mover without a radius has a size
        length, width = self.size
        return MoverState(
            xy,
            vel,
            heading,
            np.full(n, length),
            np.full(n, width),
            segments=rectangle_segments(xy, length, width, heading),
        )


class Towed:
    """A circular platform pulled on a wire by a walker (docs/method.md §7: about 2 m behind the person)."""

    def __init__(self, leader: Walker, radius: float, wire: float, start: np.ndarray | None, t_end: float) -> None:
        from ._kernels import tow

        self.tt = np.arange(0.0, t_end + 2 * TOW_DT, TOW_DT)
        lead, _, heading = leader.body(self.tt)
        if start is None:
            start = lead[0] - wire * np.array([libm.cos(heading[0]), libm.sin(heading[0])])
        self.track = tow(np.ascontiguousarray(lead), np.asarray(start, np.float64), float(wire))
        self.vel = np.gradient(self.track, TOW_DT, axis=0)
        self.lead = lead
        self.radius = radius

    def state(self, t: np.ndarray) -> MoverState:
        def at(a: np.ndarray) -> np.ndarray:
            return np.stack([np.interp(t, self.tt, a[:, 0]), np.interp(t, self.tt, a[:, 1])], 1)

        xy, vel, lead = at(self.track), at(self.vel), at(self.lead)
        heading = libm.arctan2(lead[:, 1] - xy[:, 1], lead[:, 0] - xy[:, 0])  # along the wire
        d = np.full(len(t), 2 * self.radius)
        circles = np.hstack([xy, np.full((len(t), 1), self.radius)])[:, None, :]
        return MoverState(xy, vel, heading, d, d, circles=circles)


class SensorTrack:
    """The scanner's pose: fixed, or driving along a path facing its direction of travel.

    At each waypoint where its direction changes the robot stops and turns on the spot at `turn_rate`
    (rad/s) before any pause the scene asks for, so its heading never jumps.
    """

    def __init__(self, pose: np.ndarray, path: PathSpec | None, t_end: float, turn_rate: float = np.pi / 2) -> None:
        self.pose = np.asarray(pose, np.float64)
        self.turn_rate = turn_rate
        self.timeline = None
        if path is not None:
            pts = np.asarray(path.points, np.float64)
            d = np.diff(np.vstack([pts, pts[:1]]) if path.loop else pts, axis=0)
            heading = libm.arctan2(d[:, 1], d[:, 0])
            pauses = dict(path.pauses)
            for i in range(len(pts)) if path.loop else range(1, len(pts) - 1):
                turn = abs(float(_wrap(heading[i] - heading[i - 1])))
                if turn > 0:
                    pauses[i] = pauses.get(i, 0.0) + turn / turn_rate
            self.timeline = Timeline(replace(path, pauses=pauses), t_end)

    @property
    def moves(self) -> bool:
        return self.timeline is not None

    def _turning(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(heading, yaw rate, whether turning) at times t."""
        tl = self.timeline
        assert tl is not None  # only a moving scanner turns
        heading = tl.heading(t)
        since, until = tl.standing(t)
        stopped = np.isfinite(since) & np.isfinite(until)
        nxt = tl.heading(np.where(stopped, t + np.where(stopped, until, 0.0) + 1e-6, t))
        delta = np.where(stopped, _wrap(nxt - heading), 0.0)
        need = np.abs(delta) / self.turn_rate
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(need > 0, np.clip(np.where(stopped, since, 0.0) / need, 0.0, 1.0), 1.0)
        turning = stopped & (frac < 1.0) & (need > 0)
        return _wrap(heading + delta * frac), np.where(turning, np.sign(delta) * self.turn_rate, 0.0), turning

    def poses(self, t: np.ndarray) -> np.ndarray:
        """(n, 3): x, y, heading."""
        if self.timeline is None:
            return np.repeat(self.pose[None], len(t), 0)
        return np.hstack([self.timeline.position(t), self._turning(t)[0][:, None]])

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """(n, 2) world-frame velocity, m/s."""
        return np.zeros((len(t), 2)) if self.timeline is None else self.timeline.velocity(t)

    def yaw_rate(self, t: np.ndarray) -> np.ndarray:
        """(n,) rad/s."""
        return np.zeros(len(t)) if self.timeline is None else self._turning(t)[1]


FOLLOW_DT = 0.01  # s, integration step of a following robot
FOLLOW_STOP = 0.02  # m: a following robot stands while the gap is within this of its low end


class FollowTrack:
    """A robot trailing a walking person along the person's path (world frame, metres, seconds, radians).

    The robot's arc length r along the path obeys dr/dt = speed * clip((d - low) / (high - low), 0, 1), with
    d = u - r the gap along the path to the person's arc length u (and 0 while d is within FOLLOW_STOP of
    `low`): it trails a steadily walking person at low + (high - low) * v / speed, closes in on one who stops
    until the gap is `low`, and stands there. It starts `low` behind the person's first waypoint (on the
    path's first leg, extended backwards), and faces the person's body.
    """

    def __init__(self, leader: Walker, gap: tuple[float, float], speed: float, t_end: float) -> None:
        tl = leader.timeline
        assert tl is not None  # the scene refuses a leader without a path
        low, high = gap
        self.tt = np.arange(0.0, t_end + 2 * FOLLOW_DT, FOLLOW_DT)
        u = tl.arclength(self.tt)
        r = np.empty_like(u)
        r[0] = u[0] - low
        for i in range(1, len(u)):
            d = u[i - 1] - r[i - 1]
            v = 0.0 if d - low < FOLLOW_STOP else speed * min(1.0, (d - low) / (high - low))
            r[i] = r[i - 1] + v * FOLLOW_DT
        self.xy, _ = tl.point_at(r)
        lead = tl.position(self.tt)
        self.heading = np.unwrap(libm.arctan2(lead[:, 1] - self.xy[:, 1], lead[:, 0] - self.xy[:, 0]))
        self.vel = np.gradient(self.xy, FOLLOW_DT, axis=0)
        self.omega = np.gradient(self.heading, FOLLOW_DT)

    moves = True

    def _at(self, t: np.ndarray, a: np.ndarray) -> np.ndarray:
        return np.interp(np.asarray(t, np.float64), self.tt, a)

    def poses(self, t: np.ndarray) -> np.ndarray:
        """(n, 3): x, y, heading."""
        return np.stack([self._at(t, self.xy[:, 0]), self._at(t, self.xy[:, 1]), _wrap(self._at(t, self.heading))], 1)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """(n, 2) world-frame velocity, m/s."""
        return np.stack([self._at(t, self.vel[:, 0]), self._at(t, self.vel[:, 1])], 1)

    def yaw_rate(self, t: np.ndarray) -> np.ndarray:
        """(n,) rad/s."""
        return self._at(t, self.omega)


class MountedTrack:
    """The scanner on a robot: the pose of frame `laser` = the base's pose composed with `mount` (x, y in m and
    yaw in rad, base frame); its velocity is the base's plus the base's turning about its own origin."""

    def __init__(self, base: SensorTrack | FollowTrack, mount: np.ndarray) -> None:
        self.base = base
        self.mount = np.asarray(mount, np.float64)

    @property
    def moves(self) -> bool:
        return self.base.moves

    def _offset(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.base.poses(t)
        c, s = libm.cos(p[:, 2]), libm.sin(p[:, 2])
        mx, my = self.mount[0], self.mount[1]
        return p, np.stack([c * mx - s * my, s * mx + c * my], 1)

    def poses(self, t: np.ndarray) -> np.ndarray:
        p, off = self._offset(t)
        return np.hstack([p[:, :2] + off, _wrap(p[:, 2] + self.mount[2])[:, None]])

    def velocity(self, t: np.ndarray) -> np.ndarray:
        _, off = self._offset(t)
        w = self.base.yaw_rate(t)[:, None]
        return self.base.velocity(t) + w * np.stack([-off[:, 1], off[:, 0]], 1)

    def yaw_rate(self, t: np.ndarray) -> np.ndarray:
        return self.base.yaw_rate(t)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


CROWD_CLEARANCE = 0.9  # m between walkers' centres that crowd paths try to keep
CROWD_TRIES = 30
CROWD_BLOCK = 60.0  # s: crowd paths are planned in blocks of this length
CROWD_DT = 0.1  # s: time step of the clearance checks


def crowd_people(crowd: Crowd, t_end: float, seed: np.random.SeedSequence, first_index: int) -> list[Person]:
    """`crowd.people` walkers on random crossing paths inside the area.

    Walker i's path depends only on (seed, i), on the run's length in whole minutes and on walkers 0..i-1,
    which it avoids: each leg (and each
    stop) is redrawn, or delayed by a short wait, until it keeps CROWD_CLEARANCE from the earlier walkers
    (after CROWD_TRIES attempts the leg that keeps farthest away is taken, so a packed room still fills).
    """
    out: list[Person] = []
    lo, hi = crowd.area
    # plan whole minutes so that runs of 10 s and 60 s (same seed) show the same crowd
    t_end = CROWD_BLOCK * np.ceil((t_end + 1.0) / CROWD_BLOCK)
    grid = np.arange(0.0, t_end + CROWD_BLOCK, CROWD_DT)  # earlier walkers' positions, sampled
    others = np.zeros((0, len(grid), 2))

    def gap(t0: float, t1: float, xy0: np.ndarray, xy1: np.ndarray) -> float:
        """Smallest distance to an earlier walker while moving from xy0 (at t0) to xy1 (at t1)."""
        if not len(others):
            return np.inf
        i0 = min(int(np.floor(t0 / CROWD_DT)), len(grid) - 1)
        i1 = min(int(np.ceil(t1 / CROWD_DT)), len(grid) - 1) + 1
        f = np.clip((grid[i0:i1] - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)[:, None]
        d = others[:, i0:i1] - (xy0 + (xy1 - xy0) * f)
        return float(np.sqrt((d**2).sum(-1).min()))

    for i, ss in enumerate(seed.spawn(crowd.people)):
        rng = np.random.default_rng(ss)
        speed = float(rng.uniform(*crowd.speed))
        start = rng.uniform(lo, hi)
        for _ in range(CROWD_TRIES):
            if gap(0.0, 0.0, start, start) >= CROWD_CLEARANCE:
                break
            start = rng.uniform(lo, hi)
        pauses: dict[int, float] = {}
        pts, t, start_time = [start], 0.0, 0.0
        while t <= t_end:
            here = pts[-1]
            best, best_gap = None, -1.0
            for attempt in range(CROWD_TRIES):
                p = rng.uniform(lo, hi)
                while np.hypot(*(p - here)) < 1.5:
                    p = rng.uniform(lo, hi)
                g = gap(t, t + float(np.hypot(*(p - here))) / speed, here, p)
                if g > best_gap:
                    best, best_gap = p, g
                if g >= CROWD_CLEARANCE:
                    break
                if attempt % 3 == 2 and gap(t, t + 1.0, here, here) >= CROWD_CLEARANCE:
                    # wait a moment and look again; an earlier best leg is stale now
                    if len(pts) == 1:
                        start_time += 1.0
                    else:
                        pauses[len(pts) - 1] = pauses.get(len(pts) - 1, 0.0) + 1.0
                    t += 1.0
                    best, best_gap = None, -1.0
            if best is None:
                best = p
            t += float(np.hypot(*(best - here))) / speed
            pts.append(best)
            if rng.random() < crowd.pause_probability:
                stop = float(rng.uniform(0, crowd.max_pause))
                if gap(t, t + stop, best, best) >= CROWD_CLEARANCE:
                    pauses[len(pts) - 1] = stop
                    t += stop
        path = PathSpec(np.array(pts), speed, pauses, start_time)
        out.append(Person(f"crowd{first_index + i}", Gait(leg_length=float(rng.uniform(0.8, 1.0))), path))
        others = np.concatenate([others, Timeline(path, t_end + CROWD_BLOCK).position(grid)[None]])
    return out


class World:
    """Everything the simulator needs for a run of `t_end` seconds: `objects` (the ground-truth table, in id
    order: people, platforms, boxes, columns, benches, wall corners, wall segments), `movers` (object
    index, mover), `static` geometry, `corner_walls` and the `sensor` track (a SensorTrack or FollowTrack, in a
    MountedTrack when the scene mounts the scanner on the robot: its poses are always the scanner's)."""

    def __init__(self, scene: Scene, t_end: float, seed: np.random.SeedSequence, people: int | None = None) -> None:
        self.objects: list[ObjectInfo] = []
        self.movers: list[tuple[int, Walker | Driven | Towed]] = []
        self._segs: list = []
        self._seg_own: list[int] = []
        self._circs: list = []
        self._circ_own: list[int] = []
        persons = list(scene.people)
        if scene.crowd is not None:
            crowd = scene.crowd if people is None else replace(scene.crowd, people=people)
            persons += crowd_people(crowd, t_end, seed, len(persons) + 1)
        walkers = self._add_movers(scene, persons, t_end)
        self._add_fixtures(scene)
        self.corner_walls = self._add_walls(scene)  # (corner index, wall segment index, wall segment index)
        self.static = Primitives(
            np.array(self._segs, np.float64).reshape(-1, 4),
            np.array(self._seg_own, np.int32),
            np.array(self._circs, np.float64).reshape(-1, 3),
            np.array(self._circ_own, np.int32),
        )
        placed = scene.sensor
        base: FollowTrack | SensorTrack
        if placed.follow is not None:
            base = FollowTrack(walkers[placed.follow], placed.gap, placed.follow_speed, t_end)
        else:
            base = SensorTrack(placed.pose, placed.path, t_end, placed.turn_rate)
        self.sensor = base if placed.mount is None else MountedTrack(base, placed.mount)

    def _add_movers(self, scene: Scene, persons: list[Person], t_end: float) -> dict[str, Walker]:
        walkers = {}
        for p in persons:
            walkers[p.name] = Walker(p, t_end)
            self.movers.append((self._add(CLASS_PERSON, p.name), walkers[p.name]))
        for i, pf in enumerate(scene.platforms, 1):
            if pf.pulled_by is not None:
                towed = Towed(walkers[pf.pulled_by], pf.radius, pf.wire, pf.center, t_end)
                self.movers.append((self._add(CLASS_CIRCLE_OBJECT, f"platform{i}"), towed))
            elif pf.path is not None:
                mover = Driven(pf.path, t_end, radius=pf.radius)
                self.movers.append((self._add(CLASS_CIRCLE_OBJECT, f"platform{i}"), mover))
        for i, b in enumerate(scene.boxes, 1):
            if b.path is not None:
                mover = Driven(b.path, t_end, size=(b.length, b.width))
                self.movers.append((self._add(CLASS_RECTANGULAR_OBJECT, f"box{i}"), mover))
        return walkers

    def _circle(self, k: int, centre, radius: float) -> None:
        self._circs.append([float(centre[0]), float(centre[1]), radius])
        self._circ_own.append(k)

    def _rectangle(self, k: int, centre, length: float, width: float, heading: float) -> None:
        self._segs += list(rectangle_segments(np.asarray(centre, np.float64), length, width, np.float64(heading)))
        self._seg_own += [k] * 4

    def _add_fixtures(self, scene: Scene) -> None:
        for i, pf in enumerate(scene.platforms, 1):
            if pf.pulled_by is None and pf.path is None:
                k = self._add(CLASS_CIRCLE_OBJECT, f"platform{i}", pf.center, 0.0, 2 * pf.radius, 2 * pf.radius)
                self._circle(k, pf.center, pf.radius)
        for i, b in enumerate(scene.boxes, 1):
            if b.path is None:
                k = self._add(CLASS_RECTANGULAR_OBJECT, f"box{i}", b.center, b.orientation, b.length, b.width)
                self._rectangle(k, b.center, b.length, b.width, b.orientation)
        for i, c in enumerate(scene.columns, 1):
            k = self._add(CLASS_COLUMN, f"column{i}", c.center, 0.0, 2 * c.radius, 2 * c.radius)
            self._circle(k, c.center, c.radius)
        for i, bench in enumerate(scene.benches, 1):
            a, c = bench.supports
            span = float(np.hypot(*(c - a)))
            heading = float(libm.arctan2(*(c - a)[::-1]))
            k = self._add(
                CLASS_BENCH,
                f"bench{i}",
                (a + c) / 2,
                heading,
                span + 2 * bench.support_radius,
                max(bench.seat_width, 2 * bench.support_radius),
            )
            self._circle(k, a, bench.support_radius)
            self._circle(k, c, bench.support_radius)
            if bench.seat_width > 0:
                self._rectangle(k, (a + c) / 2, span, bench.seat_width, heading)

    def _add_walls(self, scene: Scene) -> list[tuple[int, int, int]]:
        """Wall corners (vertices where a wall turns by more than CORNER_MIN_TURN), then wall segments."""
        wall_segments = []
        for w in scene.walls:
            pts = np.vstack([w.points, w.points[:1]]) if w.closed else w.points
            wall_segments.append([(pts[j], pts[j + 1]) for j in range(len(pts) - 1)])
        corners: list[tuple] = []
        for wi, w in enumerate(scene.walls):
            n_seg = len(wall_segments[wi])
            pairs = [(j, (j + 1) % n_seg) for j in range(n_seg)] if w.closed else [(j, j + 1) for j in range(n_seg - 1)]
            for a, b in pairs:
                p0, v = wall_segments[wi][a]
                p2 = wall_segments[wi][b][1]
                d1, d2 = p0 - v, p2 - v
                if np.pi - _angle_between(d1, d2) > CORNER_MIN_TURN:
                    bis = d1 / np.hypot(*d1) + d2 / np.hypot(*d2)
                    k = self._add(
                        CLASS_WALL_CORNER, f"corner{len(corners) + 1}", v, float(libm.arctan2(bis[1], bis[0]))
                    )
                    corners.append((k, wi, a, b))
        seg_index = {}
        for wi, ws in enumerate(wall_segments):
            for j, (p, q) in enumerate(ws):
                d = q - p
                k = self._add(
                    CLASS_WALL,
                    f"wall{wi + 1}.{j + 1}",
                    (p + q) / 2,
                    float(libm.arctan2(d[1], d[0])),
                    float(np.hypot(*d)),
                    0.0,
                )
                seg_index[wi, j] = k
                self._segs.append([*p, *q])
                self._seg_own.append(k)
        return [(k, seg_index[wi, a], seg_index[wi, b]) for k, wi, a, b in corners]

    def _add(
        self, cls: int, name: str, xy=None, orientation: float = 0.0, length: float = 0.0, width: float = 0.0
    ) -> int:
        xy = (np.nan, np.nan) if xy is None else (float(xy[0]), float(xy[1]))
        self.objects.append(ObjectInfo(len(self.objects) + 1, cls, name, xy, orientation, length, width))
        return len(self.objects) - 1


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    dot = a[0] * b[0] + a[1] * b[1]  # not np.dot: BLAS picks its code (FMA or not) by the CPU
    return float(libm.arccos(np.clip(dot / (np.hypot(*a) * np.hypot(*b)), -1.0, 1.0)))
