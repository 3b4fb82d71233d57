"""Tracking and classification parameters (method.md §6): one dataclass with the defaults, and TOML loading.

Units: metres, seconds, m/s. Every constant of the tracker is here, none is a literal in the code.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from pathlib import Path

from ..bounds import TRACK, check, track_combined
from ..errors import ConfigError


@dataclass(frozen=True)
class TrackingParams:
    """Parameters of `datmo track` (the `[track]` table of a config file)."""

    # Kalman filter: constant velocity, white-noise acceleration (Kohler 1997)
    process_noise: float = 2.0          # acceleration spectral density q, (m/s^2)^2 per Hz
    person_process_noise: float = 4.0   # q of tracks fed mostly by legs (people start and stop sharply)
    measurement_noise: float = 0.05     # sigma of a model-centre measurement, m
    leg_measurement_noise: float = 0.2  # sigma when one leg stands for a person's centre, m
    initial_speed_sigma: float = 1.0    # sigma of the velocity of a new track, m/s
    # association
    gate: float = 13.8                  # Mahalanobis distance squared (chi2, 2 dof, 99.9 %)
    max_gate_distance: float = 1.5      # m; no match farther than this whatever the covariance
    # life cycle
    confirm_hits: int = 3               # M hits ...
    confirm_window: int = 5             # ... in the last N scans confirm a track (M >= 2)
    delete_after: float = 0.8           # s without a hit while it should have been seen
    delete_after_occluded: float = 8.0  # s without a hit while occluded or out of view
    reacquire_speed: float = 1.5        # m/s; a lost occluded track may take a measurement it could reach
    reacquire_distance: float = 4.0     # m; ... but none farther than this from where it was last seen
    occlusion_margin: float = 0.3       # m; a return this much nearer than a track hides it
    tentative_delete_after: float = 0.5  # s without a hit for a track never confirmed
    # classification (method.md §6)
    d_max: float = 1.5                  # segments larger than this are static, m
    undefined_window: float = 1.0       # s a small circle or blob stays undefined (X)
    moving_distance: float = 0.5        # m from its first position before a track can be dynamic
    moving_speed: float = 0.2           # m/s, filtered speed above which a track is moving
    moving_time: float = 1.0            # s of moving at consecutive hits before a track is dynamic
    # people
    leg_radius_max: float = 0.2         # circles up to this radius may be legs, m
    leg_blob_max: float = 0.35          # blobs up to this size may be legs, m
    stride_max: float = 0.9             # legs farther apart than this are not one person, m
    leg_reach: float = 0.6              # a person track takes legs this near its predicted centre, m
    leg_beside: float = 0.55            # a lone leg this near a person track just seen is its other leg, m
    spawn_clearance: float = 0.2        # no new track this near an existing one, m
    step_min: float = 0.1               # legs must each lead by this much to show the walking pattern, m
    walking_after: float = 0.4          # s of moving before the legs' alternation counts as walking
    step_max: float = 1.0               # an along-track leg separation above 2 l sin(theta) bound, m
    merge_distance: float = 0.55        # two leg or person tracks nearer than this are one, m ...
    merge_speed: float = 0.5            # ... when one is tentative or their velocities differ less, m/s
    person_votes: float = 0.5           # share of a track's hits that were leg measurements for a person
    # people with a leg detector: leg_score follows the leg probability of a track's recent hits
    leg_probability: float = 0.5        # segments the detector gives at least this are legs (paired into people)
    leg_evidence_rate: float = 0.25     # weight of each new hit in the running mean (about 1/rate hits remembered)
    person_evidence: float = 0.6        # a track is a person while that running leg probability is at least this
    moving_person_evidence: float = 0.35  # ... or this, once it is dynamic (clutter that passes for legs stays put)
    person_pairs: int = 3               # a person not dynamic has been seen with two legs this many times
    moving_person_pairs: int = 1        # ... and a dynamic one
    carried_travel: float = 1.0         # m; a track the sensor has carried this far ...
    carried_radius: float = 0.1         # m; ... moving in the sensor frame less than this (running mean) is no person
    # background: a grid of how long each place was hit by a return (tracking frame); a leg candidate on a place
    # occupied for long (a wall, a bench, a column) is not a leg (real perception finds leg-sized pieces there)
    background_time: float = 3.0        # s a place must have been hit, never seen through, to be background; 0: off
    background_cell: float = 0.1        # m, grid cell
    background_extent: float = 40.0     # m, the grid spans this much either side of the first sensor pose
    # a log without odometry whose scanner moves: track in poses estimated from the scans (scan matching)
    ego_motion: str = "auto"            # "auto": when the scenery changes and the estimate moves; "on"; "off"
    # output
    tail_length: int = 20               # trajectory points in each track's marker tail

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **changes) -> TrackingParams:
        """A copy with `changes` (keys checked; None values ignored)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        return from_dict({**self.to_dict(), **changes})


def from_dict(values: dict, where: str = "track") -> TrackingParams:
    """TrackingParams from a mapping, checking names, types and ranges (bounds.TRACK); ConfigError names the
    key, the value and the allowed range."""
    known = {f.name for f in fields(TrackingParams)}
    out = {}
    for key, value in values.items():
        if key not in known:
            raise ConfigError(f"{where}.{key}: unknown parameter (known: {', '.join(sorted(known))})")
        if key == "ego_motion":
            if value not in ("auto", "on", "off"):
                raise ConfigError(f"{where}.{key}: one of auto, on, off; got {value!r}")
            out[key] = value
        else:
            out[key] = check(TRACK[key], value, f"{where}.{key}")
    params = TrackingParams(**out)
    track_combined(params, where)
    return params


def load_toml(path: str | Path) -> TrackingParams:
    """Parameters from the `[track]` table of a TOML file (or its top level when it has no such table)."""
    from ..config import read_table

    return from_dict(read_table(path, "track"), where=f"{path}: track")
