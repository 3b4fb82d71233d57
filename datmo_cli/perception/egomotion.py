"""Ego-motion from the scans themselves: the sensor's pose at every scan of a run without odometry.

Method: scan-to-local-map ICP. Each scan is thinned to at most `max_points` sensor-frame points and matched
with point-to-line residuals (point-to-point where the map has no line, at corners and posts) against a map
of the last few keyframe scans, held in a hashed grid; a shrinking correspondence gate under Huber weights,
then Geman-McClure weights, keep moving people and other changes from pulling the fit. Each scan starts
from the constant-velocity prediction; when few points fit or ICP does not converge, it is retried from
the previous pose turned or driven on by a few set moves, and the best fit kept. Matching against keyframes
rather than the previous scan means a still scanner estimates its first pose up to noise that never
accumulates, and a slow one drifts only when the keyframe changes. Kernels are in scan_odometry.py and icp.py.

Frames and units: scans in the sensor frame (x forward, y left); poses (x, y in metres, theta in radians)
in the "scan_odom" frame, whose origin is the first scan's sensor pose (x along its forward axis).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from datmo_cli.base import libm

from ..logs.scan import Odometry, ScanGeometry, ScanRun

FRAME_ID = "scan_odom"
#: retries' starting moves from the previous pose (x, y m, theta rad, in its sensor frame): standing or driving
#: on 0.5 or 1 m, each turning 0, 15, 30 or 45 degrees either way (a robot that starts to turn or drive breaks
#: the constant-velocity guess; thinned logs such as CARMEN's corrected ones jump that far between scans)
DEFAULT_RECOVERY_MOVES = tuple(
    (x, 0.0, math.radians(a)) for x in (0.0, 0.5, 1.0) for a in (0.0, -15.0, 15.0, -30.0, 30.0, -45.0, 45.0)
)


@dataclass
class EgoMotion:
    """Poses estimated from the scans and how well each scan matched.

    odometry: the sensor's pose at every scan stamp (frame FRAME_ID, child the scan's frame id);
    residual (N,): mean |point-to-line residual| of the matched points, m (0 for the first scan and failures);
    inlier_share (N,): share of the scan's points with a residual <= inlier_tol; matched (N,): points with
    a map point within the final gate; points (N,): points used; keyframe, recovered (a retry from turned
    guesses won), failed (too few matches: the constant-velocity prediction kept) (N,) bool; iterations (N,):
    Gauss-Newton iterations spent, retries included.
    """

    odometry: Odometry
    residual: np.ndarray
    inlier_share: np.ndarray
    matched: np.ndarray
    points: np.ndarray
    keyframe: np.ndarray
    recovered: np.ndarray
    failed: np.ndarray
    iterations: np.ndarray

    @property
    def poses(self) -> np.ndarray:
        """(N, 3) x, y (m), theta (rad) in FRAME_ID."""
        o = self.odometry
        return np.stack([o.x, o.y, o.theta], axis=1)


@functools.lru_cache(maxsize=8)
def _beam_trig(geometry: ScanGeometry) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of the beam angles, made once per geometry (align_scans asks for them on every pair; the
    kernels only read them)."""
    a = geometry.angles()
    return np.ascontiguousarray(libm.cos(a)), np.ascontiguousarray(libm.sin(a))


def _max_window(geometry: ScanGeometry) -> int:
    """Beams either side searched for a normal's neighbours: about 10 degrees, 3 to 40 beams."""
    step = abs(geometry.angle_increment) or math.radians(1.0)
    return int(min(40, max(3, math.ceil(math.radians(10.0) / step))))


@dataclass(frozen=True)
class IcpParams:
    """Settings of the scan matcher. Distances in metres, angles in radians.

    max_points: points per scan matched (thinned to source_spacing apart along the scan, then strided);
    map_spacing: spacing of keyframe points in the map; normal_radius, max_gap, planarity: a map point gets
    a line normal when its beam neighbours (about normal_radius each side, in steps of at most max_gap) are
    line-like (minor / major spread <= planarity); max_dist0 -> max_dist: the correspondence gate, halved
    each iteration (max_dist is also the grid's cell size); robust_scale: residual scale of the Huber, then
    Geman-McClure, weights; inlier_tol: residual that counts as an inlier; max_iter: Gauss-Newton iterations
    per match; prior_weight: pull toward the prediction (in points' worth), for directions the scene leaves
    free; keyframe_dist / keyframe_angle / keyframe_share: when a scan becomes a keyframe (that far from the
    newest, or that few inliers); n_keyframes: keyframes in the local map; min_inlier_share: below it (or
    when ICP does not converge), retry from the previous pose moved by each of recovery_moves ((x, y, theta)
    in its sensor frame) and keep the best share.
    """

    max_points: int = 300
    source_spacing: float = 0.05
    map_spacing: float = 0.03
    normal_radius: float = 0.1
    max_gap: float = 0.5
    planarity: float = 0.3
    max_dist0: float = 0.5
    max_dist: float = 0.25
    robust_scale: float = 0.05
    inlier_tol: float = 0.05
    max_iter: int = 30
    prior_weight: float = 1.0
    keyframe_dist: float = 0.3
    keyframe_angle: float = math.radians(10.0)
    keyframe_share: float = 0.5
    n_keyframes: int = 3
    min_inlier_share: float = 0.5
    recovery_moves: tuple[tuple[float, float, float], ...] = DEFAULT_RECOVERY_MOVES

    def __post_init__(self) -> None:
        if self.max_points < 16:
            raise ValueError(f"max_points must be at least 16, got {self.max_points}")
        if not (0 < self.max_dist <= self.max_dist0):
            raise ValueError(f"need 0 < max_dist <= max_dist0, got {self.max_dist} and {self.max_dist0}")
        if self.n_keyframes < 1:
            raise ValueError(f"n_keyframes must be at least 1, got {self.n_keyframes}")
        if not (self.source_spacing >= 0 and self.map_spacing >= 0 and self.robust_scale > 0 and self.max_iter >= 1):
            raise ValueError("source_spacing and map_spacing must be >= 0, robust_scale > 0, max_iter >= 1")


def estimate_egomotion(run: ScanRun, **params) -> EgoMotion:
    """The sensor's motion over `run`, estimated from its scans alone (see the module docstring); keyword
    parameters are the fields of IcpParams. Invalid returns (inf, NaN, <= range_min, >= range_max) are
    ignored."""
    p = IcpParams(**params)
    if len(run) == 0:
        raise ValueError("no scans")
    from . import scan_odometry as KO

    g = run.geometry
    cos_a, sin_a = _beam_trig(g)
    dt = np.zeros(len(run))
    dt[1:] = np.diff(run.stamps) * 1e-9
    poses = np.zeros((len(run), 3))
    stats = np.zeros((len(run), KO.N_STATS))
    KO.odometry_run(
        run.ranges,
        dt,
        (cos_a, sin_a, float(g.range_min), float(g.range_max)),
        (int(p.max_points), float(p.source_spacing), float(p.map_spacing)),
        (float(p.normal_radius), float(p.max_gap), _max_window(g), float(p.planarity)),
        (
            float(p.max_dist0),
            float(p.max_dist),
            float(p.robust_scale),
            float(p.inlier_tol),
            int(p.max_iter),
            float(p.prior_weight),
        ),
        (float(p.keyframe_dist), float(p.keyframe_angle), float(p.keyframe_share), int(p.n_keyframes)),
        (float(p.min_inlier_share), np.asarray(p.recovery_moves, np.float64).reshape(-1, 3)),
        poses,
        stats,
    )
    odom = Odometry(
        run.stamps.copy(),
        poses[:, 0].copy(),
        poses[:, 1].copy(),
        poses[:, 2].copy(),
        frame_id=FRAME_ID,
        child_frame_id=g.frame_id,
    )
    flags = stats[:, KO.S_FLAGS].astype(np.int64)
    return EgoMotion(
        odom,
        stats[:, KO.S_RESIDUAL].copy(),
        stats[:, KO.S_INLIER_SHARE].copy(),
        stats[:, KO.S_MATCHED].astype(np.int64),
        stats[:, KO.S_POINTS].astype(np.int64),
        (flags & KO.FLAG_KEYFRAME) != 0,
        (flags & KO.FLAG_RECOVERED) != 0,
        (flags & KO.FLAG_FAILED) != 0,
        stats[:, KO.S_ITERATIONS].astype(np.int64),
    )


def estimate_odometry(run: ScanRun, *, max_points: int = IcpParams.max_points, **params) -> Odometry:
    """The sensor's pose at every scan of `run`, estimated from the scans (no wheel odometry): frame
    "scan_odom" (FRAME_ID), origin at the first scan's sensor pose, x, y in metres, theta in radians, child
    frame the scan's frame id. Keyword parameters are the fields of IcpParams."""
    return estimate_egomotion(run, max_points=max_points, **params).odometry


def align_scans(
    reference: np.ndarray,
    ranges: np.ndarray,
    geometry: ScanGeometry,
    init: tuple[float, float, float] = (0.0, 0.0, 0.0),
    **params,
) -> tuple[np.ndarray, dict]:
    """Pose (x, y m, theta rad) of the scan `ranges` in the sensor frame of the scan `reference` (both of
    `geometry`, (B,) ranges in m), by one ICP from init; and its figures: matched, residual (mean |r|, m),
    inlier_share, iterations. Keyword parameters are the fields of IcpParams (the keyframe and recovery
    ones unused)."""
    p = IcpParams(**params)
    from . import icp
    from . import scan_odometry as KO

    g = geometry
    cos_a, sin_a = _beam_trig(g)
    lo, hi, b = float(g.range_min), float(g.range_max), g.n_beams
    ref = np.ascontiguousarray(reference, np.float32)
    cur = np.ascontiguousarray(ranges, np.float32)
    if ref.shape != (b,) or cur.shape != (b,):
        raise ValueError(f"scans must have {b} beams, got {ref.shape} and {cur.shape}")
    px, py, beams = np.zeros(b), np.zeros(b), np.zeros(b, np.int64)
    m = KO.scan_points(ref, cos_a, sin_a, lo, hi, p.map_spacing, b, px, py, beams)
    nx, ny = np.zeros(b), np.zeros(b)
    KO.scan_normals(
        ref, (cos_a, sin_a, lo, hi), beams, m, (p.normal_radius, p.max_gap, _max_window(g), p.planarity), nx, ny
    )
    local_map = icp.new_local_map(b, p.max_dist)
    icp.add_to_map((px, py, nx, ny), m, (0.0, 0.0, 0.0), 0.0, local_map, 0)
    sx, sy = np.zeros(b), np.zeros(b)
    n = KO.scan_points(cur, cos_a, sin_a, lo, hi, p.source_spacing, p.max_points, sx, sy, beams)
    pose = np.zeros(3)
    settings = (p.max_dist0, p.max_dist, p.robust_scale, p.inlier_tol, p.max_iter, p.prior_weight)
    matched, residual, inliers, iters = icp.icp_align(
        (sx, sy), n, (float(init[0]), float(init[1]), float(init[2])), local_map, settings, pose
    )
    return pose, {
        "matched": int(matched),
        "residual": float(residual),
        "inlier_share": inliers / max(n, 1),
        "iterations": int(iters),
    }


def path_length(odometry: Odometry) -> float:
    """Distance travelled along the poses, metres (on a still scanner this sums the estimate's jitter, a few
    mm a scan)."""
    return float(np.hypot(np.diff(odometry.x), np.diff(odometry.y)).sum())


def total_turn(odometry: Odometry) -> float:
    """Sum of |heading change| between consecutive poses, radians."""
    d = np.diff(odometry.theta)
    return float(np.abs(libm.arctan2(libm.sin(d), libm.cos(d))).sum())


def is_moving(odometry: Odometry, min_path: float = 0.3, min_turn: float = math.radians(20.0)) -> bool:
    """Whether the scanner really moves: its farthest excursion from the first pose is over min_path (m) or
    its heading strays over min_turn (rad) from the first. Excursions, not summed path, so jitter of a still
    scanner's estimate does not add up over a long log."""
    if len(odometry) < 2:
        return False
    reach = float(np.hypot(odometry.x - odometry.x[0], odometry.y - odometry.y[0]).max())
    d = odometry.theta - odometry.theta[0]
    turn = float(np.abs(libm.arctan2(libm.sin(d), libm.cos(d))).max())
    return reach > min_path or turn > min_turn


EGO_MOTION_MODES = ("auto", "on", "off")
EGO_SAMPLE_SCANS = 1024  # "auto" judges whether the scanner moves on a log's first scans (one block), not all


def sampled_scans(n: int) -> int:
    """How many of a log's n first scans "auto" samples pairs from (EGO_SAMPLE_SCANS at most)."""
    return min(n, EGO_SAMPLE_SCANS)


def scans_move(
    run: ScanRun, samples: int = 100, min_step: float = 0.05, min_turn: float = math.radians(1.5), share: float = 0.1
) -> bool:
    """Whether a log's scanner moves, cheaply: up to `samples` pairs of consecutive scans, spread over its first
    EGO_SAMPLE_SCANS scans (a streamed log decides before its first block is processed, without reading the
    whole log an extra time), are aligned by one ICP each (align_scans); it moves when at least `share` of them
    (and 3) are over min_step (m) or min_turn (rad) apart. A still scanner's pairs agree within about 1 cm,
    people walking by included (simulated and real still logs: 90 % of pairs within 3 cm); a robot at walking
    pace moves 8-13 cm a scan."""
    if len(run) < 2:
        return False
    n = sampled_scans(len(run))
    picks = pair_picks(n, samples)
    order = np.stack([picks, picks + 1], axis=1).ravel()
    pairs = ScanRun(run.stamps[order], run.ranges[order], run.geometry)
    return pairs_move(pairs, n, samples, min_step, min_turn, share)


def pair_picks(n: int, samples: int = 100) -> np.ndarray:
    """The first scans k of the pairs (k, k + 1) scans_move aligns among n scans (sampled_scans of a log)."""
    if n < 2:
        return np.zeros(0, np.int64)
    return np.unique(np.linspace(0, n - 2, min(samples, n - 1)).astype(np.int64))


def pairs_move(
    pairs: ScanRun,
    n: int,
    samples: int = 100,
    min_step: float = 0.05,
    min_turn: float = math.radians(1.5),
    share: float = 0.1,
) -> bool:
    """scans_move's decision on its pairs already gathered (rows 2i and 2i + 1 of `pairs`, from n sampled
    scans; see pair_picks)."""
    if n < 2:
        return False
    m = len(pairs) // 2
    need = max(3, int(np.ceil(share * len(pair_picks(n, samples)))))
    moved = 0
    for i in range(m):
        pose, _ = align_scans(pairs.ranges[2 * i], pairs.ranges[2 * i + 1], pairs.geometry)
        if np.hypot(pose[0], pose[1]) > min_step or abs(pose[2]) > min_turn:
            moved += 1
            if moved >= need:
                return True
    return False


def odometry_for(run: ScanRun, odometry: Odometry | None, mode: str = "auto") -> tuple[Odometry | None, bool]:
    """The odometry to track a run in, and whether it was estimated here: the log's own when it has one;
    otherwise, with mode "on", or "auto" when the scanner moves (scans_move, then is_moving on the full
    estimate), the poses estimated from the scans; else None (a still scanner: track in its sensor frame)."""
    if mode not in EGO_MOTION_MODES:
        raise ValueError(f"ego-motion mode {mode!r} is not one of {', '.join(EGO_MOTION_MODES)}")
    if (odometry is not None and len(odometry)) or mode == "off" or len(run) < 2:
        return odometry, False
    if mode == "auto" and not scans_move(run):
        return None, False
    estimate = estimate_odometry(run)
    if mode == "auto" and not is_moving(estimate):
        return None, False
    return estimate, True
