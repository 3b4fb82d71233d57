"""People from a moving robot, against ground truth (make accuracy): the simulated scenes
`following` (a robot trailing a person, no /odom: datmo estimates the motion by scan matching) and `lab-drive` (a
robot with odometry among standing and walking people, its laser mounted 0.85 m ahead and yawed 40°), each
simulated in a temporary folder and run through datmo's real pipeline as `datmo run` runs it.

For tuning, call `scene_run` (simulate, run, load) and the figure functions on it, or `following_figures` and
`lab_drive_figures`; `python -m benchmarks accuracy scenes` prints every figure beside its target.

Matching (positions in the sensor frame, metres): in each scan, confirmed tracks (STATUS_CONFIRMED) and the
visible ground-truth objects in question are paired one to one within MATCH_RADIUS (0.5 m, as `datmo evaluate`),
nearest first (an optimal assignment). "People" are every ground-truth person, standing ones included.

Figures (and their targets):
- following: the leader's (ground-truth id 1) share of its frames in view where the track matched to it is a
  person (>= 0.95); the same over the passers-by (>= 0.90); people MOTA (>= 0.90: CLEAR-MOT over the people in
  view, tracks classified person as hypotheses, everything else a don't-care region, as `datmo evaluate`'s
  per-class figure) and its ID switches per person-minute in view (<= 1).
- lab-drive: the longest time a confirmed track on a static thing (matched to no ground-truth person and no object
  that moves in that scan: walls, fixtures) stays dynamic, counted in consecutive scans (<= 1 s), with
  where it was; people standing (whole run, and stop-and-start people while stopped): share of their frames
  matched by a track that is static and a person (>= 0.90); people walking: share of their frames matched by a
  dynamic track (the issue: "walkers dynamic"; taken as >= 0.90); people MOTA (>= 0.80); and whether `datmo run`
  on the scene's ROS 1 bag (`simulate -o NAME.bag`, mount only on /tf) gives the tracks it gives on the MCAP,
  message for message.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.common import print_lines
from datmo_cli.logs.vocabulary import CLASS_PERSON, MOBILITY_DYNAMIC, MOBILITY_STATIC, STATUS_CONFIRMED

MATCH_RADIUS = 0.5  # m
LEADER_ID = 1  # the following scene's first [[person]]
TARGETS = {
    "leader person share": (">=", 0.95),
    "passers person share": (">=", 0.90),
    "people MOTA": (">=", 0.90),
    "ID switches per person-minute": ("<=", 1.0),
    "longest dynamic on a static thing s": ("<=", 1.0),
    "standing people static and person": (">=", 0.90),
    "walking people dynamic": (">=", 0.90),
    "lab-drive people MOTA": (">=", 0.80),
    "ROS 1 bag gives the same tracks": ("==", True),
}


@dataclass
class SceneRun:
    """A simulated scene tracked by datmo: per scan k, ground-truth objects gt[gt_offsets[k]:gt_offsets[k + 1]]
    (datmo_msgs/GroundTruthObject) and tracks tracks[tr_offsets[k]:tr_offsets[k + 1]] (datmo_msgs/Track), the
    two aligned scan for scan; `period` s between scans; `tracked`: the output log (None for hand-made runs)."""

    gt_offsets: np.ndarray
    gt: np.ndarray
    tr_offsets: np.ndarray
    tracks: np.ndarray
    period: float
    stamps: np.ndarray | None = None
    sensor_theta: np.ndarray | None = None
    tracked: Path | None = None

    @property
    def frames(self) -> int:
        return len(self.gt_offsets) - 1


# ------------------------------------------------------------------------------------------ simulate and run


def simulate(scene: str, out: Path, *, seed: int = 0, duration: float | None = None) -> Path:
    """`datmo simulate --scene SCENE --seed SEED [--duration D] -o OUT` in process: an MCAP with ground truth, or a
    ROS 1 bag when OUT ends in .bag."""
    from datmo_cli.logs import mcapio
    from datmo_cli.passes.simulated import write_simulation, write_simulation_bag
    from datmo_cli.sim.simulate import Simulation

    sim = Simulation(scene, seed=seed, duration=duration)
    if Path(out).suffix == ".bag":
        write_simulation_bag(out, sim, force=True)
    else:
        with mcapio.LogWriter(out, force=True) as writer:
            write_simulation(writer, sim)
    return Path(out)


def process(src: Path, out: Path, config=None) -> Path:
    """`datmo run SRC` for one input (a bag converted by the importers first, as `datmo run` converts it), into
    OUT; `config`: a datmo_cli.passes.config.DatmoConfig (None: the defaults)."""
    from datmo_cli.passes import pipeline
    from datmo_cli.passes.input_logs import scan_log

    with scan_log(Path(src), Path(out), force=True, tell=lambda _line: None) as log:
        pipeline.process_file(log, out, force=True, config=config, markers=False, origin=src)
    return Path(out)


def load(truth_log: Path, tracked_log: Path) -> SceneRun:
    """The ground truth of `truth_log` and the tracks of `tracked_log` (the same scans), aligned by stamp."""
    from datmo_cli.logs import mcapio, types
    from datmo_cli.report import decode_channel

    truth = mcapio.read_log(truth_log, topics=[mcapio.TOPIC_GROUND_TRUTH])
    gt = decode_channel(types.GROUND_TRUTH, truth.messages[mcapio.TOPIC_GROUND_TRUTH][1])
    log = mcapio.read_log(tracked_log, topics=[mcapio.TOPIC_TRACKS])
    tr = decode_channel(types.TRACKS, log.messages[mcapio.TOPIC_TRACKS][1])
    if not np.array_equal(gt.stamps, tr.stamps):
        raise ValueError(f"{tracked_log}: its tracks are not stamped like {truth_log}'s ground truth")
    period = float(np.median(np.diff(gt.stamps))) * 1e-9 if len(gt.stamps) > 1 else 0.1
    return SceneRun(
        gt.offsets["objects"],
        gt.items["objects"],
        tr.offsets["tracks"],
        tr.items["tracks"],
        period,
        gt.stamps,
        gt.scalars.get("sensor_theta"),
        Path(tracked_log),
    )


def scene_run(scene: str, folder: Path, *, seed: int = 0, duration: float | None = None, config=None) -> SceneRun:
    """Simulate `scene` in `folder`, run datmo on it, and load both."""
    folder = Path(folder)
    log = simulate(scene, folder / f"{scene}.mcap", seed=seed, duration=duration)
    return load(log, process(log, folder / f"{scene}-tracked.mcap", config))


# ------------------------------------------------------------------------------------------------- matching


def _assign(tx: np.ndarray, ty: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(track index, target index) pairs of an optimal one-to-one assignment within MATCH_RADIUS."""
    from scipy.optimize import linear_sum_assignment

    if not len(tx) or not len(gx):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    d = np.hypot(tx[:, None] - gx[None, :], ty[:, None] - gy[None, :])
    r, c = linear_sum_assignment(np.where(d <= MATCH_RADIUS, d, 1e9))
    ok = d[r, c] <= MATCH_RADIUS
    return r[ok], c[ok]


def match(run: SceneRun, target) -> np.ndarray:
    """For every ground-truth row (run.gt), the row in run.tracks of the confirmed track matched to it, or -1
    (unmatched, or not a target). `target(objects)`: which of a scan's ground-truth objects are matched."""
    out = np.full(len(run.gt), -1, np.int64)
    for k in range(run.frames):
        g0, t0 = run.gt_offsets[k], run.tr_offsets[k]
        g, t = run.gt[g0 : run.gt_offsets[k + 1]], run.tracks[t0 : run.tr_offsets[k + 1]]
        gi = np.flatnonzero(target(g) & (g["visible"] == 1))
        ti = np.flatnonzero(t["status"] == STATUS_CONFIRMED)
        r, c = _assign(
            t["x"][ti].astype(float), t["y"][ti].astype(float), g["x"][gi].astype(float), g["y"][gi].astype(float)
        )
        out[g0 + gi[c]] = t0 + ti[r]
    return out


def _people(g: np.ndarray) -> np.ndarray:
    return g["classification"] == CLASS_PERSON


# --------------------------------------------------------------------------------------------------- figures


def person_share(run: SceneRun, ids, matched: np.ndarray | None = None) -> float | None:
    """Share of the frames in which a person of `ids` is in view (visible) where the confirmed track matched to
    it is classified person (None: never in view)."""
    matched = match(run, _people) if matched is None else matched
    rows = np.isin(run.gt["id"], list(ids)) & (run.gt["visible"] == 1) & _people(run.gt)
    if not rows.any():
        return None
    m = matched[rows]
    return float(np.mean((m >= 0) & (run.tracks["classification"][np.maximum(m, 0)] == CLASS_PERSON)))


def people_ids(run: SceneRun) -> list[int]:
    return sorted(set(run.gt["id"][_people(run.gt)].astype(int).tolist()))


def people_mota(run: SceneRun) -> dict:
    """CLEAR-MOT over the people in view (standing ones too), tracks classified person as hypotheses, every other
    ground-truth object a don't-care region (datmo_cli.evaluate); {"mota", "switches", "person_minutes",
    "switches_per_person_minute"}."""
    from datmo_cli import evaluate as ev

    n = run.frames
    stamps = run.stamps if run.stamps is not None else np.arange(n, dtype=np.int64) * int(run.period * 1e9)
    gt = ev.Frames(
        np.asarray(stamps, np.int64),
        np.asarray(run.gt_offsets, np.int64),
        run.gt["id"].astype(np.int64),
        run.gt["x"].astype(np.float64),
        run.gt["y"].astype(np.float64),
        run.gt["classification"].astype(np.int64),
    )
    target = _people(run.gt) & (run.gt["visible"] == 1)
    theta = np.zeros(n) if run.sensor_theta is None else np.asarray(run.sensor_theta, np.float64)
    frame = np.repeat(np.arange(n), np.diff(run.gt_offsets))
    other = ~target
    counts = np.bincount(frame[other], minlength=n)
    regions = ev.Regions(
        np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        gt.x[other],
        gt.y[other],
        run.gt["orientation"][other].astype(np.float64) - theta[frame[other]],
        run.gt["length"][other].astype(np.float64) / 2,
        run.gt["width"][other].astype(np.float64) / 2,
    )
    hyps = ev.track_frames(stamps, run.tr_offsets, run.tracks)
    scores = ev.evaluate(gt.select(target), hyps, regions=regions, match_radius=MATCH_RADIUS)
    person = scores.get("person", {})
    minutes = float(target.sum()) * run.period / 60.0
    switches = person.get("num_switches", 0)
    return {
        "mota": person.get("mota"),
        "switches": switches,
        "person_minutes": minutes,
        "switches_per_person_minute": switches / minutes if minutes > 0 else None,
    }


GT_CLASSES = {
    1: "person",
    2: "circle object",
    3: "rectangular object",
    4: "column",
    5: "bench",
    6: "wall corner",
    7: "wall",
}


def nearest(run: SceneRun, k: int, x: float, y: float) -> str:
    """The ground-truth object of scan k nearest to (x, y) (sensor frame; distance to its extent, an oriented
    length x width rectangle), e.g. "wall 23 at 0.04 m"."""
    g = run.gt[run.gt_offsets[k] : run.gt_offsets[k + 1]]
    if not len(g):
        return "nothing"
    theta = 0.0 if run.sensor_theta is None else float(run.sensor_theta[k])
    a = g["orientation"].astype(float) - theta
    dx, dy = x - g["x"].astype(float), y - g["y"].astype(float)
    u = np.maximum(np.abs(np.cos(a) * dx + np.sin(a) * dy) - g["length"] / 2, 0)
    v = np.maximum(np.abs(-np.sin(a) * dx + np.cos(a) * dy) - g["width"] / 2, 0)
    d = np.hypot(u, v)
    i = int(np.argmin(d))
    return f"{GT_CLASSES.get(int(g['classification'][i]), 'object')} {int(g['id'][i])} at {d[i]:.2f} m"


def longest_dynamic_on_static(run: SceneRun) -> dict:
    """The longest run of consecutive scans in which one confirmed track, matched to no ground-truth person and no
    object that moves in that scan, is dynamic (the issue's "wall or static piece"; a person who stops is scored by
    standing_static_person_share): {"seconds", "track", "at_s" (when the run began, s), "on" (the nearest
    ground-truth object when it began, see `nearest`)}."""
    moving = match(run, lambda g: (g["moving"] == 1) | _people(g))
    on_moving = np.zeros(len(run.tracks), bool)
    on_moving[moving[moving >= 0]] = True
    best = {"seconds": 0.0, "track": None, "at_s": None, "on": None}
    since: dict[int, tuple[int, int]] = {}  # track id -> (first scan of its run, first row)
    for k in range(run.frames):
        rows = np.arange(run.tr_offsets[k], run.tr_offsets[k + 1])
        t = run.tracks[rows]
        bad = (t["status"] == STATUS_CONFIRMED) & (t["mobility"] == MOBILITY_DYNAMIC) & ~on_moving[rows]
        now = {int(i): since.get(int(i), (k, int(r))) for i, r in zip(t["id"][bad], rows[bad], strict=True)}
        since = now
        for i, (k0, r0) in since.items():
            seconds = (k - k0 + 1) * run.period
            if seconds > best["seconds"]:
                best = {"seconds": seconds, "track": i, "at_s": k0 * run.period, "on": (k0, r0)}
    if best["on"] is not None:
        k0, r0 = best["on"]
        best["on"] = nearest(run, k0, float(run.tracks["x"][r0]), float(run.tracks["y"][r0]))
    return best


def standing_static_person_share(run: SceneRun, matched: np.ndarray | None = None) -> float | None:
    """Share of the frames of people standing in view (ground truth not moving) matched by a confirmed track that
    is static and classified person (None: nobody stands in view)."""
    matched = match(run, _people) if matched is None else matched
    rows = _people(run.gt) & (run.gt["visible"] == 1) & (run.gt["moving"] == 0)
    if not rows.any():
        return None
    m = matched[rows]
    t = run.tracks[np.maximum(m, 0)]
    return float(np.mean((m >= 0) & (t["mobility"] == MOBILITY_STATIC) & (t["classification"] == CLASS_PERSON)))


def walking_dynamic_share(run: SceneRun, matched: np.ndarray | None = None) -> float | None:
    """Share of the frames of people walking in view matched by a confirmed dynamic track (None: nobody walks)."""
    matched = match(run, _people) if matched is None else matched
    rows = _people(run.gt) & (run.gt["visible"] == 1) & (run.gt["moving"] == 1)
    if not rows.any():
        return None
    m = matched[rows]
    return float(np.mean((m >= 0) & (run.tracks["mobility"][np.maximum(m, 0)] == MOBILITY_DYNAMIC)))


def same_tracks(a: Path, b: Path) -> tuple[bool, int, int]:
    """(whether two tracked logs hold the same /datmo/tracks messages, how many are the same, how many a has)."""
    from datmo_cli.logs import mcapio

    pa = mcapio.read_messages(a, mcapio.TOPIC_TRACKS)[1]
    pb = mcapio.read_messages(b, mcapio.TOPIC_TRACKS)[1]
    same = sum(x == y for x, y in zip(pa, pb, strict=False))
    return len(pa) == len(pb) and same == len(pa), same, len(pa)


def following_figures(folder: Path, *, seed: int = 0, duration: float | None = None, config=None) -> dict:
    run = scene_run("following", folder, seed=seed, duration=duration, config=config)
    matched = match(run, _people)
    passers = [i for i in people_ids(run) if i != LEADER_ID]
    mota = people_mota(run)
    return {
        "leader person share": person_share(run, [LEADER_ID], matched),
        "passers person share": person_share(run, passers, matched),
        "people MOTA": mota["mota"],
        "ID switches per person-minute": mota["switches_per_person_minute"],
        "_mota": mota,
        "_scans": run.frames,
    }


def lab_drive_figures(
    folder: Path, *, seed: int = 0, duration: float | None = None, config=None, bag: bool = True
) -> dict:
    folder = Path(folder)
    run = scene_run("lab-drive", folder, seed=seed, duration=duration, config=config)
    matched = match(run, _people)
    mota = people_mota(run)
    out = {
        "longest dynamic on a static thing s": longest_dynamic_on_static(run),
        "standing people static and person": standing_static_person_share(run, matched),
        "walking people dynamic": walking_dynamic_share(run, matched),
        "lab-drive people MOTA": mota["mota"],
        "_mota": mota,
        "_scans": run.frames,
    }
    if bag:
        src = simulate("lab-drive", folder / "lab-drive-robot.bag", seed=seed, duration=duration)
        tracked = process(src, folder / "lab-drive-robot-tracked.mcap", config)
        out["ROS 1 bag gives the same tracks"] = same_tracks(run.tracked, tracked)
    return out


# ----------------------------------------------------------------------------------------------------- print


def _verdict(name: str, value) -> str:
    op, target = TARGETS[name]
    if value is None:
        return "n/a"
    ok = value >= target if op == ">=" else value <= target if op == "<=" else value == target
    return "meets" if ok else "MISSES"


def lines(folder: Path) -> list[str]:
    out = []
    f = following_figures(folder / "following")
    out.append(f"following ({f['_scans']} scans, no /odom: poses by scan matching)")
    for name in ("leader person share", "passers person share", "people MOTA", "ID switches per person-minute"):
        v = f[name]
        text = "n/a" if v is None else f"{v:.3f}"
        op, target = TARGETS[name]
        out.append(f"  {name:38s} {text:>8s}   target {op} {target:g}   {_verdict(name, v)}")
    m = f["_mota"]
    out.append(f"  ({m['switches']} ID switches over {m['person_minutes']:.1f} person-minutes in view)")
    lab = lab_drive_figures(folder / "lab-drive")
    out.append(f"lab-drive ({lab['_scans']} scans, odometry, laser 0.85 m ahead yawed 40°)")
    worst = lab["longest dynamic on a static thing s"]
    name = "longest dynamic on a static thing s"
    where = "" if worst["track"] is None else f" (track {worst['track']} on {worst['on']} from {worst['at_s']:.1f} s)"
    out.append(f"  {name:38s} {worst['seconds']:8.1f}   target <= 1   {_verdict(name, worst['seconds'])}{where}")
    for name in ("standing people static and person", "walking people dynamic", "lab-drive people MOTA"):
        v = lab[name]
        text = "n/a" if v is None else f"{v:.3f}"
        op, target = TARGETS[name]
        out.append(f"  {name:38s} {text:>8s}   target {op} {target:g}   {_verdict(name, v)}")
    same, n_same, n = lab["ROS 1 bag gives the same tracks"]
    name = "ROS 1 bag gives the same tracks"
    out.append(
        f"  {name:38s} {'yes' if same else 'no':>8s}   target yes   {_verdict(name, same)} "
        f"({n_same} of {n} Tracks messages identical)"
    )
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "following").mkdir()
        (folder / "lab-drive").mkdir()
        print_lines("People from a moving robot, simulated (following and lab-drive)", lines(folder))


if __name__ == "__main__":
    main()
