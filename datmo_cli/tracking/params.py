"""Tracking and classification parameters (docs/method.md §6): the `[track]` section, each field declared with its
default, range and help.

Units: metres, seconds, m/s. Every constant of the tracker is here, none is a literal in the code.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..base.bounds import D_MAX, NO_SENSE, PROBABILITY, SHARE, Section, param, track_combined
from ..base.bounds import bound as _b
from .state import P_TAIL_LENGTH, PARAM_NAMES

_HOUR = "an hour: longer waits are no tracking"
_ACCELERATION = "√1000 ≈ 32 m/s² of acceleration noise is beyond any walker or vehicle"
_SIGMA = "sigmas of metres are no measurement"


@dataclass(frozen=True)
class TrackingParams(Section):
    """The `[track]` table of a config file: parameters of `datmo track`."""

    name: ClassVar[str] = "track"
    # numeric fields the Python around the tracking kernels reads, not the kernels (not in state.PARAM_NAMES):
    # hindsight_lag (the pipeline's hold-back), free_space_scans (sizes the tracker's ring of kept scans)
    not_in_kernels: ClassVar[tuple[str, ...]] = ("hindsight_lag", "free_space_scans")
    removed: ClassVar[dict[str, str]] = {
        "leg_probability": "the leg threshold is the leg model's own (threshold_p, chosen by datmo train-legs)",
        "moving_person_evidence": "a person's class no longer depends on its mobility (see person_evidence)",
        "moving_person_pairs": "a person's class no longer depends on its mobility (see person_pairs)",
    }

    # Kalman filter: constant velocity, white-noise acceleration (Kohler 1997)
    process_noise: float = param(
        2.0,
        _b(0, 1000, "(m/s²)²/Hz", _ACCELERATION, open_=True),
        "White-noise acceleration variance q (spectral density).",
    )
    person_process_noise: float = param(
        4.0,
        _b(0, 1000, "(m/s²)²/Hz", _ACCELERATION, open_=True),
        "q of tracks fed mostly by legs (people start and stop sharply).",
    )
    measurement_noise: float = param(0.05, _b(0, 10, "m", _SIGMA, open_=True), "Sigma of a measured model centre.")
    leg_measurement_noise: float = param(
        0.2, _b(0, 10, "m", _SIGMA, open_=True), "Sigma when one leg stands for a person's centre."
    )
    initial_speed_sigma: float = param(1.0, _b(0, 100, "m/s"), "Sigma of the velocity of a new track.")
    # association
    gate: float = param(
        13.8,
        _b(0, 1000, "", "chi² with 2 dof; 1000 already passes anything", open_=True),
        "Gate on the squared Mahalanobis distance (13.8: chi² 2 dof 99.9 %).",
    )
    max_gate_distance: float = param(
        1.5, _b(0, 100, "m", NO_SENSE), "No match farther than this whatever the covariance."
    )
    # life cycle
    confirm_hits: int = param(
        3,
        _b(2, 16, "scans", "no track confirmed from one scan; 16 bits of history", integer=True),
        "M: a track is confirmed after M hits ...",
    )
    confirm_window: int = param(
        5, _b(2, 16, "scans", "16 bits of hit history", integer=True), "... N: in its last N scans."
    )
    delete_after: float = param(
        0.8, _b(0, 3600, "s", _HOUR), "Seconds a confirmed track lives unseen when it should be seen."
    )
    delete_after_occluded: float = param(
        8.0, _b(0, 3600, "s", _HOUR), "Seconds a confirmed track lives unseen while hidden behind a nearer return."
    )
    delete_after_out_of_view: float = param(
        8.0,
        _b(0, 3600, "s", _HOUR),
        "Seconds a confirmed track lives unseen outside the field of view or beyond the range (a person at least "
        "person_coast).",
    )
    reacquire_speed: float = param(
        1.5, _b(0, 50, "m/s"), "A lost occluded track may take a measurement it could reach at this speed ..."
    )
    reacquire_distance: float = param(
        4.0, _b(0, 100, "m", NO_SENSE), "... but none farther than this from where it was last seen."
    )
    occlusion_margin: float = param(0.3, _b(0, 10, "m"), "A return this much nearer than a track hides it.")
    tentative_delete_after: float = param(0.5, _b(0, 3600, "s", _HOUR), "Seconds a track never confirmed lives unseen.")
    # classification (docs/method.md §6)
    d_max: float = param(
        1.5,
        D_MAX,
        "Objects larger than this are static: the paper's d_max, one parameter whose home is [features] d_max.",
        same_as="features.d_max",
    )
    undefined_window: float = param(1.0, _b(0, 3600, "s", _HOUR), "Seconds a small circle or blob stays undefined.")
    moving_distance: float = param(
        0.5, _b(0, 100, "m", NO_SENSE), "Distance from its first position before a track can be dynamic."
    )
    moving_speed: float = param(0.2, _b(0, 50, "m/s"), "Filtered speed above which a track is moving.")
    moving_time: float = param(
        1.0, _b(0, 3600, "s", _HOUR), "Seconds of moving at consecutive hits before a track is dynamic."
    )
    still_time: float = param(
        1.0,
        _b(0, 3600, "s", _HOUR),
        "With the leg detector, seconds at a speed below moving_speed after which a dynamic "
        "track is static again (a person who stops; the paper's rule keeps it dynamic).",
    )
    # people
    leg_radius_max: float = param(0.2, _b(0, 2, "m"), "Circles up to this radius may be legs.")
    leg_blob_max: float = param(0.35, _b(0, 2, "m"), "Blobs up to this size may be legs.")
    stride_max: float = param(0.9, _b(0, 5, "m"), "Legs farther apart than this are not one person.")
    leg_reach: float = param(0.6, _b(0, 5, "m"), "A person track takes legs this near its predicted centre.")
    leg_beside: float = param(0.55, _b(0, 5, "m"), "A lone leg this near a person track just seen is its other leg.")
    spawn_clearance: float = param(0.2, _b(0, 10, "m"), "No new track this near an existing one.")
    step_min: float = param(0.1, _b(0, 5, "m"), "Legs must each lead by this much to show the walking pattern.")
    walking_after: float = param(
        0.4, _b(0, 3600, "s", _HOUR), "Seconds of moving before the legs' alternation counts as walking."
    )
    step_max: float = param(1.0, _b(0, 5, "m"), "Bound of an along-track leg separation, above 2 l sin(theta).")
    merge_distance: float = param(0.55, _b(0, 10, "m"), "Two leg or person tracks nearer than this are one ...")
    merge_speed: float = param(
        0.5, _b(0, 50, "m/s"), "... when one is tentative or their velocities differ less than this."
    )
    person_votes: float = param(
        0.5, _b(0, 1, "", SHARE), "Share of a track's hits that were leg measurements for a person."
    )
    # people with a leg detector (the person life cycle, see Tracker): evidence is the mean leg probability of a
    # track's leg-candidate hits (other hits leave it as it is); a track becomes a person once, from paired legs,
    # and stays one until its evidence falls below person_maintain or it dies; unseen, it coasts person_coast s
    leg_evidence_rate: float = param(
        0.1,
        _b(0, 1, "", "a share; 0 would never learn", open_=True),
        "Weight of each leg-candidate hit in the evidence (a plain mean over the first "
        "1/rate such hits, then a running mean that remembers about 1/rate of them).",
    )
    person_evidence: float = param(
        0.6, _b(0, 1, "", PROBABILITY), "A confirmed track becomes a person when its evidence is at least this ..."
    )
    person_maintain: float = param(
        0.2, _b(0, 1, "", PROBABILITY), "... and stays one until its evidence falls below this."
    )
    person_pairs: int = param(
        1, _b(0, 1_000_000, "scans", integer=True), "... and it has been seen with two legs this many times."
    )
    person_coast: float = param(
        3.0, _b(0, 3600, "s", _HOUR), "Seconds a person lives unseen (output flagged occluded), predicted on."
    )
    person_radius: float = param(
        0.4,
        _b(0, 5, "m"),
        "Returns this near a person, or a track of evidence at least person_evidence, are theirs: they never "
        "become background.",
    )
    # free space: a track becomes a person from person_evidence once one of its legs was seen where kept earlier
    # scans saw through (a place, not a mobility: static leg-like clutter never is); else only from this much
    person_evidence_unfree: float = param(
        0.85,
        _b(0, 1, "", PROBABILITY),
        "A confirmed track whose legs were never seen in free space becomes a person only at this evidence.",
    )
    free_space_scans: int = param(
        0,
        _b(0, 1000, "scans", "each kept scan holds its ranges", integer=True),
        "Earlier scans kept for the free-space test (0: no test, every leg counts as in free space) ...",
    )
    free_space_interval: float = param(0.25, _b(0, 3600, "s", _HOUR), "... one kept every this many seconds ...")
    free_space_min: int = param(
        2,
        _b(1, 1000, "scans", integer=True),
        "... a leg is in free space when at least this many of them saw through its place (returned more than "
        "occlusion_margin beyond it, or nothing within range) ...",
    )
    free_space_share: float = param(
        0.5, _b(0, 1, "", SHARE), "... and at least this share of those that had its place in view."
    )
    restart_jump: float = param(
        0.0,
        _b(0, 100, "m", NO_SENSE),
        "A track that missed and is taken back farther than this from its prediction restarts there, without "
        "velocity (0: never).",
    )
    person_hold: int = param(
        1,
        _b(0, 1, "", "a switch", integer=True),
        "1: a person with a leg candidate within leg_reach takes no measurement that is no leg candidate.",
    )
    background_shield: float = param(
        1.0,
        _b(0, 1, "", PROBABILITY),
        "Returns within person_radius of a track of leg evidence at least this never feed the background "
        "(1: only people's).",
    )
    # carried: a beam whose return stays put in the sensor frame while the sensor travels sees a part of the robot
    carried_travel: float = param(
        1.0,
        _b(0, 1000, "m"),
        "A beam whose return stays within carried_radius while the sensor travels this "
        "far sees something the robot carries: no leg there ...",
    )
    carried_radius: float = param(0.05, _b(0, 10, "m"), "... (metres of range from where it first returned).")
    # background: a grid of how long each place was hit by a return (tracking frame); a leg candidate on a place
    # occupied for long (a wall, a bench, a column) is not a leg (real perception finds leg-sized pieces there)
    background_time: float = param(
        3.0,
        _b(0, 3600, "s", "0 turns the background off"),
        "Seconds a place must have been hit, never seen through, to be background (0: no background).",
    )
    background_cell: float = param(0.1, _b(0.05, 10, "m", "finer cells only grow the grid"), "Background grid cell.")
    background_extent: float = param(
        40.0,
        _b(0, 100, "m", "the grid's memory grows with its square", open_=True),
        "The background grid spans this much either side of the first sensor pose.",
    )
    # a log without odometry whose scanner moves: track in poses estimated from the scans (scan matching)
    ego_motion: str = param(
        "auto",
        choices=("auto", "on", "off"),
        help="For a log without /odom: track in poses estimated by scan matching (written to "
        "/odom, frame scan_odom) when the scanner moves ('auto'), always ('on') or never "
        "('off').",
    )
    # output
    hindsight_lag: float = param(
        1.0,
        _b(0, 60, "s", "a minute of tracks held back; the memory held grows with the lag"),
        "Batch outputs (datmo run, datmo track) smooth each track over this lag (a fixed-lag RTS smoother) and "
        "label a track promoted to person within it a person from its first confirmed scan; the live paths "
        "(node, play, record --live) stay causal (0: off).",
    )
    tail_length: int = param(
        20,
        _b(0, 10_000, "points", "each track holds its tail", integer=True),
        "Trajectory points in each track's marker tail.",
    )

    @classmethod
    def combined(cls, params: TrackingParams, where: str) -> None:
        track_combined(params, where)

    def kernel_vector(self, leg_threshold: float = 0.5) -> np.ndarray:
        """The parameters as the tracking kernels read them: one float64 vector indexed by state.P_* (in the
        order of state.PARAM_NAMES; units as the fields; tail_length at least 1), then P_LEG_THRESHOLD: the
        leg detector's threshold (its model's threshold_p; a leg candidate scored at least this is a leg)."""
        out = np.array([float(getattr(self, name)) for name in PARAM_NAMES] + [float(leg_threshold)], np.float64)
        out[P_TAIL_LENGTH] = max(self.tail_length, 1)
        return out
