"""The multi-object tracker: one `step` per scan composes predict, associate, update, life cycle and
classification (docs/method.md §6; association, occlusion and life cycle are datmo's additions).

Tracking frame: the sensor frame of a still scanner, or the world (odometry) frame when each step is given
the sensor's pose. Time comes from the scan stamps (ns), so uneven rates and dropped scans are handled.
Life cycle: a track starts tentative; it is confirmed after `confirm_hits` hits in the last
`confirm_window` scans (never from one scan); a confirmed track that misses is coasting; a track is deleted
after `delete_after` s without a hit while it should have been seen, `delete_after_occluded` s while a nearer
return covers its bearing, or `delete_after_out_of_view` s out of the field of view or range.

The work of a scan is one compiled call (_step.track_scan, on the track table of state.py); a block of scans
is one call too (`Tracker.track_block`). This class holds the state between calls and converts inputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datmo_cli.base import libm

from ..logs import cdr, types
from ..logs.scan import ScanGeometry
from . import state
from .bundles import Blobs, Circles, FeatureBlock, FeatureOffsets, Legs, Lines, ScanMeasurements
from .measurements import KIND_BLOB, KIND_CIRCLE, KIND_LEG, KIND_PERSON, KIND_RECT, N_KINDS, Measurements, ScanFeatures
from .params import TrackingParams

TRACK_DTYPE = cdr.element_dtype(types.TRACK)
# which measurement kinds (columns) a confirmed track may take, by the kind group that fed it most (rows:
# legs, circles, lines, blobs, -, a lone leg; see _association.kind_group); tentative tracks (row 4) take any
_COMPAT = np.ones((6, N_KINDS), bool)
_COMPAT[0, [KIND_CIRCLE, KIND_RECT]] = False
_COMPAT[1, KIND_PERSON] = False  # a circle partly seen may pass for a leg, or for a line
_COMPAT[2, [KIND_PERSON, KIND_LEG, KIND_CIRCLE]] = False
_ANY, _LONE_LEG = 4, 5
_COMPAT[_LONE_LEG, [KIND_PERSON, KIND_CIRCLE, KIND_RECT]] = False
# with a leg detector, a leg it was less sure of is a small circle or blob: people may take those too
_COMPAT_LEARNED = _COMPAT.copy()
_COMPAT_LEARNED[[0, _LONE_LEG], KIND_CIRCLE] = True
# which kinds a lost track may be reacquired on (rows as _COMPAT's): only its own (a person: two legs or one), since
# with real perception the clutter around (pieces of walls and benches as blobs, short lines and small circles) is
# near everywhere
_REACQUIRE = np.zeros((6, N_KINDS), bool)
_REACQUIRE[0, KIND_PERSON] = _REACQUIRE[1, KIND_CIRCLE] = _REACQUIRE[2, KIND_RECT] = True
_REACQUIRE[3, KIND_BLOB] = _REACQUIRE[_ANY] = _REACQUIRE[_LONE_LEG, KIND_LEG] = True
# with a leg detector a lost person may be taken back on one leg too (the detector vouches for it; a leg beside a
# confirmed track just hit is never taken)
_REACQUIRE_LEARNED = _REACQUIRE.copy()
_REACQUIRE_LEARNED[0, KIND_LEG] = True


_LEG_DTYPE = cdr.element_dtype(types.LEG)


@dataclass
class TrackBlock:
    """What tracking a block of N scans gave: the live tracks of scan i are items[offsets[i]:offsets[i + 1]]
    (Track elements), their tails tail[...] (rows of (T, 2) positions, tracking frame, m) and tail_count."""

    offsets: np.ndarray  # (N + 1,) int64
    items: np.ndarray  # Track elements
    tail: np.ndarray  # (len(items), T, 2) float64
    tail_count: np.ndarray  # (len(items),) int64


def _flat(features: list[ScanFeatures]) -> FeatureBlock:
    """The compiled block's feature arrays: per kind, per-scan offsets and contiguous fields (float64 for
    coordinates, int64 for beams, segments and kinds), as a bundles.FeatureBlock."""
    f8, i8 = np.float64, np.int64

    def join(name: str, dtype: np.dtype) -> tuple[np.ndarray, np.ndarray]:
        # the scans' structured arrays joined as bytes: np.concatenate of structured arrays costs ~20 µs each
        parts = [getattr(f, name) for f in features]
        counts = np.fromiter((0 if a is None else len(a) for a in parts), np.int64, len(parts))
        offsets = np.zeros(len(parts) + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])
        same = {id(dtype)}  # dtypes found equal to `dtype` (comparing structured dtypes costs ~1 µs)
        chunks = []
        for a in parts:
            if a is None:
                continue
            if id(a.dtype) not in same:
                if a.dtype != dtype:
                    a = np.asarray(a).astype(dtype)
                else:
                    same.add(id(a.dtype))
            chunks.append(a.tobytes())
        return offsets, np.frombuffer(b"".join(chunks), dtype)

    def fields(name: str, dtype: np.dtype, bundle: type[Circles | Blobs | Lines | Legs]) -> tuple:
        """(offsets, the bundle of this kind's fields, named as the message's)."""
        offsets, a = join(name, dtype)
        names = bundle._fields
        return offsets, bundle(*(a[n].astype(i8 if n in ("first", "last", "segment", "kind") else f8) for n in names))

    circle_at, circles = fields("circles", _CIRCLE_DTYPE, Circles)
    blob_at, blobs = fields("blobs", _BLOB_DTYPE, Blobs)
    line_at, lines = fields("lines", _LINE_DTYPE, Lines)
    leg_at, legs = fields("legs", _LEG_DTYPE, Legs)
    return FeatureBlock(FeatureOffsets(circle_at, blob_at, line_at, leg_at), circles, blobs, lines, legs)


_CIRCLE_DTYPE = cdr.element_dtype(types.CIRCLE)
_BLOB_DTYPE = cdr.element_dtype(types.BLOB)
_LINE_DTYPE = cdr.element_dtype(types.LINE)


class Tracker:
    """Tracks and classifies objects scan by scan. `step` takes one scan's measurements (sensor frame)
    and returns the live tracks as Track elements (element_dtype(types.TRACK)); `track_block` tracks many
    scans' features in one compiled call.

    People, with a leg detector (`learned`), have a life cycle with hysteresis:
    - Every leg candidate (a cluster the detector scored above 0) reaches the tracker with its probability p.
      Candidates of p >= `leg_threshold` (the model's own threshold) are legs: paired within a stride into
      people, or single; the others are measured as their shape (circle, line or blob) carrying their p.
    - A track's evidence is the mean p of its leg-candidate hits (a plain mean of the first 1/leg_evidence_rate,
      then a running mean of that rate); hits on anything else leave it unchanged; a candidate on the background
      or carried sets it to 0.
    - With the free-space test on (free_space_scans > 0), a leg is in free space where kept earlier scans saw
      through its place (_people.in_free_space); a track one of whose legs was keeps that (sticky). With it off,
      every leg counts as in free space.
    - A confirmed track becomes a person once it has been seen with two legs person_pairs times and its evidence
      is at least person_evidence with its legs once in free space, or person_evidence_unfree without; it stays a
      person until its evidence falls below person_maintain or it dies. Walking is not required (someone
      standing, or followed by a robot, is a person) and mobility plays no part.
    - A person with a leg candidate within leg_reach takes no measurement that is no leg candidate (person_hold);
      with restart_jump > 0, a track that missed and is taken back farther than it from its prediction restarts
      there (no velocity).
    - Unseen, a person coasts person_coast s on its prediction (at least delete_after_occluded s while hidden
      behind a nearer return, delete_after_out_of_view s out of view, as every track), output flagged occluded,
      and may be taken back by a measurement it could have reached (as an occluded track is).
    - Returns within person_radius of a person, or of a track of evidence at least background_shield, never feed
      the background grid, and a leg candidate near a person is theirs even on the background.
    - A beam whose return keeps its place in the sensor frame while the sensor travels carried_travel sees a part
      of the robot: candidates on such beams are not legs, and a track that takes one loses its evidence.
    With the paper's rule, a person needs paired legs and the walking pattern (legs leading in turn)."""

    def __init__(
        self,
        params: TrackingParams | None = None,
        geometry: ScanGeometry | None = None,
        learned: bool = False,
        leg_threshold: float = 0.5,
    ) -> None:
        self.params = params or TrackingParams()
        self.learned = learned
        self.leg_threshold = float(leg_threshold)
        self.geometry = geometry
        self.tracks = state.TrackTable(self.params.tail_length)
        self.stamp_ns: int | None = None
        self.pose: np.ndarray | None = None
        self._prm = self.params.kernel_vector(self.leg_threshold)
        self._ctx = state.new_context()
        self._t0: int | None = None  # ns of the first scan: the table's times count from it
        self._compat = _COMPAT_LEARNED if learned else _COMPAT
        self._reacquire = _REACQUIRE_LEARNED if learned else _REACQUIRE
        self._rules = (self.learned, self._compat, self._reacquire)  # the compiled step's `rules`
        self._out = np.zeros(64, TRACK_DTYPE)
        p = self.params
        if geometry is not None:
            angles = geometry.angle_min + geometry.angle_increment * np.arange(geometry.n_beams)
            self._cos, self._sin = libm.cos(angles), libm.sin(angles)
            self._geo = np.array(
                [geometry.angle_min, geometry.angle_increment, geometry.range_max, 1.0, geometry.range_min], np.float64
            )
        else:
            self._cos = self._sin = np.zeros(0)
            self._geo = np.array([0.0, 1.0, np.inf, 0.0, 0.0])
        if geometry is not None and p.background_time > 0:
            # background grid (see _background.background_update): score and mark per cell, the active cells and their
            # range and beam
            n = int(np.ceil(2 * p.background_extent / p.background_cell))
            self._bg = (np.zeros(n * n), np.zeros(n * n, np.int64), np.zeros(65536, np.int64), np.zeros((65536, 2)))
        else:
            self._bg = (np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))
        # carried beams (see _background.carried_update): per beam, the range it keeps returning and the travel (m) it
        # was seen there and away
        # and the scans kept for the free-space test (see _people.keep_scan): ranges (K, B) m, poses (K, 3)
        B = geometry.n_beams if geometry is not None else 0
        K = p.free_space_scans if geometry is not None else 0
        self._carry = (
            np.full(B, np.nan),
            np.zeros(B),
            np.zeros(B),
            np.zeros((K, B), np.float32),
            np.zeros((K, 3)),
        )

    @property
    def next_id(self) -> int:
        return int(self._ctx[state.C_NEXT_ID])

    def _relative(self, stamp_ns: int) -> int:
        if self._t0 is None:
            self._t0 = int(stamp_ns)
        self.stamp_ns = int(stamp_ns)
        return int(stamp_ns) - self._t0

    # ---------------------------------------------------------------------------------------- step
    def step(
        self,
        stamp_ns: int,
        meas: Measurements | ScanFeatures,
        ranges: np.ndarray | None = None,
        pose: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance to the scan at `stamp_ns` (ns) with its measurements or features `meas` (sensor frame),
        its ranges (m, for the occlusion test and the background; None: no missed track counts as occluded)
        and the sensor's world pose (x, y in m, theta in rad) when tracking in the world frame. Returns the
        live tracks (Track elements)."""
        if isinstance(meas, ScanFeatures):
            block = self.track_block(
                np.array([stamp_ns], np.int64),
                [meas],
                None if ranges is None else np.asarray(ranges, np.float32)[None, :],
                None if pose is None else np.asarray(pose, np.float64)[None, :],
            )
            return block.items
        from . import _scan_measurements, _step

        stamp = self._relative(stamp_ns)
        self.pose = None if pose is None else np.asarray(pose, np.float64)
        raw = np.asarray(meas.raw_legs, np.float64)
        has_prob = raw.shape[1] >= 4
        raw5 = np.zeros((len(raw), _scan_measurements.RAW_COLS))
        raw5[:, _scan_measurements.R_COVER] = -1.0
        raw5[:, : min(raw.shape[1], _scan_measurements.RAW_COLS)] = raw[:, : _scan_measurements.RAW_COLS]
        c8 = np.ascontiguousarray
        meas_arrays = ScanMeasurements(
            c8(meas.x, np.float64),
            c8(meas.y, np.float64),
            c8(meas.size, np.float64),
            c8(meas.kind, np.int64),
            c8(meas.legs, np.float64).reshape(-1, 4),
            raw5,
            c8(meas.prob, np.float64),
        )
        sensor = (
            np.zeros(0, np.float32) if ranges is None else c8(ranges, np.float32),
            ranges is not None,
            pose is not None,
            np.zeros(3) if pose is None else c8(pose, np.float64),
            self._geo,
        )
        tab, self._out = _step.step_measurements(
            self.tracks.table,
            self._ctx,
            self._prm,
            np.int64(stamp),
            meas_arrays,
            has_prob,
            sensor,
            (self._cos, self._sin),
            self._bg,
            self._carry,
            self._rules,
            self._out,
        )
        self.tracks.table = tab
        self.tracks.n = n = int(self._ctx[state.C_N_TRACKS])
        return self._out[:n].copy()

    def track_block(
        self,
        stamps: np.ndarray,
        features: list[ScanFeatures],
        ranges: np.ndarray | None = None,
        poses: np.ndarray | None = None,
        tails: bool = True,
    ) -> TrackBlock:
        """Track N scans in one compiled call: stamps (N,) ns, their features (sensor frame), ranges (N, B)
        m or None, the sensor's world poses (N, 3: x, y m, theta rad) or None (track in the sensor frame).
        Features become measurements by the paper's rule or with the learned legs
        (_scan_measurements.paper_measurements, learned_measurements).
        `tails`: give every track's tail at every scan too (for the markers; else TrackBlock.tail is empty)."""
        from . import _step

        N = len(stamps)
        stamps = np.asarray(stamps, np.int64)
        if N == 0:
            T = self.tracks.tail_length
            return TrackBlock(
                np.zeros(1, np.int64), np.zeros(0, TRACK_DTYPE), np.zeros((0, T, 2)), np.zeros(0, np.int64)
            )
        self._relative(int(stamps[0]))
        assert self._t0 is not None  # set by _relative
        rel = stamps - np.int64(self._t0)
        self.stamp_ns = int(stamps[-1])
        self.pose = None if poses is None else np.asarray(poses[-1], np.float64)
        ranges_arg = (
            np.zeros((N, 0), np.float32) if ranges is None else np.ascontiguousarray(ranges, np.float32).reshape(N, -1)
        )
        poses_arg = np.zeros((N, 3)) if poses is None else np.ascontiguousarray(poses, np.float64).reshape(N, 3)
        cap = N * (len(self.tracks) + 4)  # grown in the call when more tracks live
        T = self.tracks.tail_length
        offsets = np.zeros(N + 1, np.int64)
        scans = (rel, ranges_arg, ranges is not None, poses_arg, poses is not None)
        output = (
            np.zeros(cap, TRACK_DTYPE),
            tails,
            np.zeros((cap if tails else 0, T, 2)),
            np.zeros(cap if tails else 0, np.int64),
            offsets,
        )
        tab, out, tail, count = _step.track_block(
            self.tracks.table,
            self._ctx,
            self._prm,
            scans,
            _flat(features),
            self._geo,
            (self._cos, self._sin),
            self._bg,
            self._carry,
            self._rules,
            output,
        )
        self.tracks.table = tab
        self.tracks.n = int(self._ctx[state.C_N_TRACKS])
        end = offsets[-1] if tails else 0
        return TrackBlock(offsets, out[: offsets[-1]], tail[:end], count[:end])

    def output(self) -> np.ndarray:
        """The live tracks as Track elements: positions in the sensor frame and, with a pose, the world."""
        from . import _step

        out = np.zeros(len(self.tracks), TRACK_DTYPE)
        _step.write_tracks(
            out,
            0,
            self.tracks.table,
            len(self.tracks),
            self.pose is not None,
            np.zeros(3) if self.pose is None else self.pose,
        )
        return out
