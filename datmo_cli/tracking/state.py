"""The tracker's state as numbers: a fixed-capacity track table, a parameter vector and a few scalars.

Track table: one C-contiguous float64 array (capacity, N_COLUMNS), one row per track, live tracks in rows
0..n-1 in creation order; the columns are named by the constants below. Counters, flags, classes and ids
are stored as float64 (exact for integers below 2**53). Times are ns since the tracker's first scan, so
they are exact too. Positions and velocities are in the tracking frame (the sensor frame of a still
scanner, or the world frame when the steps are given poses), m and m/s; P is the 4x4 covariance of
(x, y, vx, vy), row-major. The last 2 * tail_length columns are a ring buffer of recent positions (m).
When a scan spawns more tracks than the table holds, the compiled step returns a table of twice the
capacity (growth policy: doubling; rows are never dropped).

Parameters: TrackingParams as one float64 vector (TrackingParams.kernel_vector, in the order of PARAM_NAMES),
indexed by the P_* constants, and after them P_LEG_THRESHOLD, the leg detector's threshold (not a [track] field: the
leg model's own, LegModel.threshold_p).
Context: the tracker's scalars between scans (last stamp, next id, background grid bookkeeping), one
float64 vector indexed by the C_* constants.
"""

from __future__ import annotations

import numpy as np

# ------------------------------------------------------------------------------------------ track table
ID = 0
X, Y, VX, VY = 1, 2, 3, 4  # state (tracking frame), m and m/s
P0 = 5  # P[r, s] at column P0 + 4 r + s
BORN = 21  # ns since the tracker's first scan
LAST_HIT = 22  # ns of the last hit, same origin
AGE, HITS, MISSES = 23, 24, 25  # scans
HISTORY = 26  # bit mask of hits in the last confirm_window scans
VOTES = 27  # hits per measurement kind: columns VOTES + KIND_* (5 columns)
LEAD_LEFT, LEAD_RIGHT = 32, 33  # 0/1: the left (right) leg was seen leading
MOVING_TIME = 34  # s of consecutive hits with a speed above moving_speed
SIZE = 35  # largest extent seen, m
FIRST_X, FIRST_Y = 36, 37  # position when created, m
LAST_X, LAST_Y = 38, 39  # position after the last hit, m
CONFIRMED, OCCLUDED, HIT = 40, 41, 42  # 0/1
CLS, MOBILITY = 43, 44  # class and mobility (datmo_msgs/Track's classification, mobility)
TAIL_COUNT = 45  # positions written to the tail so far
LEG_SCORE = 46  # leg evidence: mean of the leg detector's probability of its leg-candidate hits
ON_BG = 47  # 0/1: took a measurement on the background this scan
IS_PERSON = 48  # 0/1: a person (with a leg detector: set once from paired legs, kept until the
# evidence falls below person_maintain or the track dies)
LEG_HITS = 49  # leg-candidate hits folded into LEG_SCORE
STILL_TIME = 50  # s of a speed at most moving_speed (a dynamic track this still is static again)
FREE = 51  # 0/1 (sticky): one of its legs was seen where kept earlier scans saw through (free space)
TAIL = 52  # tail point i at columns TAIL + 2 i (x), TAIL + 2 i + 1 (y)
N_FIXED = TAIL

# ------------------------------------------------------------------------------------- parameter vector
# The [track] keys the tracking kernels read, in slot order (TrackingParams.kernel_vector); P_<KEY> is the slot
# of <key>. tests/test_param_slots.py checks that every key has its slot, every slot is read by a kernel, and every
# [track] key is here or listed as read elsewhere (TrackingParams.not_in_kernels).
PARAM_NAMES = (
    "process_noise",
    "person_process_noise",
    "measurement_noise",
    "leg_measurement_noise",
    "initial_speed_sigma",
    "gate",
    "max_gate_distance",
    "confirm_hits",
    "confirm_window",
    "delete_after",
    "delete_after_occluded",
    "delete_after_out_of_view",
    "reacquire_speed",
    "reacquire_distance",
    "occlusion_margin",
    "tentative_delete_after",
    "d_max",
    "undefined_window",
    "moving_distance",
    "moving_speed",
    "moving_time",
    "still_time",
    "leg_radius_max",
    "leg_blob_max",
    "stride_max",
    "leg_reach",
    "leg_beside",
    "spawn_clearance",
    "step_min",
    "walking_after",
    "step_max",
    "merge_distance",
    "merge_speed",
    "person_votes",
    "leg_evidence_rate",
    "person_evidence",
    "person_maintain",
    "person_pairs",
    "person_coast",
    "person_radius",
    "person_evidence_unfree",
    "free_space_interval",
    "free_space_min",
    "free_space_share",
    "restart_jump",
    "person_hold",
    "background_shield",
    "carried_travel",
    "carried_radius",
    "background_time",
    "background_cell",
    "background_extent",
    "tail_length",
)
N_PARAMS = len(PARAM_NAMES)


def _slot(key: str) -> int:
    """The slot of [track] key `key` in the vector (a key not in PARAM_NAMES fails the import)."""
    return PARAM_NAMES.index(key)


P_PROCESS_NOISE = _slot("process_noise")
P_PERSON_PROCESS_NOISE = _slot("person_process_noise")
P_MEASUREMENT_NOISE = _slot("measurement_noise")
P_LEG_MEASUREMENT_NOISE = _slot("leg_measurement_noise")
P_INITIAL_SPEED_SIGMA = _slot("initial_speed_sigma")
P_GATE = _slot("gate")
P_MAX_GATE_DISTANCE = _slot("max_gate_distance")
P_CONFIRM_HITS = _slot("confirm_hits")
P_CONFIRM_WINDOW = _slot("confirm_window")
P_DELETE_AFTER = _slot("delete_after")
P_DELETE_AFTER_OCCLUDED = _slot("delete_after_occluded")
P_DELETE_AFTER_OUT_OF_VIEW = _slot("delete_after_out_of_view")
P_REACQUIRE_SPEED = _slot("reacquire_speed")
P_REACQUIRE_DISTANCE = _slot("reacquire_distance")
P_OCCLUSION_MARGIN = _slot("occlusion_margin")
P_TENTATIVE_DELETE_AFTER = _slot("tentative_delete_after")
P_D_MAX = _slot("d_max")
P_UNDEFINED_WINDOW = _slot("undefined_window")
P_MOVING_DISTANCE = _slot("moving_distance")
P_MOVING_SPEED = _slot("moving_speed")
P_MOVING_TIME = _slot("moving_time")
P_STILL_TIME = _slot("still_time")
P_LEG_RADIUS_MAX = _slot("leg_radius_max")
P_LEG_BLOB_MAX = _slot("leg_blob_max")
P_STRIDE_MAX = _slot("stride_max")
P_LEG_REACH = _slot("leg_reach")
P_LEG_BESIDE = _slot("leg_beside")
P_SPAWN_CLEARANCE = _slot("spawn_clearance")
P_STEP_MIN = _slot("step_min")
P_WALKING_AFTER = _slot("walking_after")
P_STEP_MAX = _slot("step_max")
P_MERGE_DISTANCE = _slot("merge_distance")
P_MERGE_SPEED = _slot("merge_speed")
P_PERSON_VOTES = _slot("person_votes")
P_LEG_EVIDENCE_RATE = _slot("leg_evidence_rate")
P_PERSON_EVIDENCE = _slot("person_evidence")
P_PERSON_MAINTAIN = _slot("person_maintain")
P_PERSON_PAIRS = _slot("person_pairs")
P_PERSON_COAST = _slot("person_coast")
P_PERSON_RADIUS = _slot("person_radius")
P_PERSON_EVIDENCE_UNFREE = _slot("person_evidence_unfree")
P_FREE_SPACE_INTERVAL = _slot("free_space_interval")
P_FREE_SPACE_MIN = _slot("free_space_min")
P_FREE_SPACE_SHARE = _slot("free_space_share")
P_RESTART_JUMP = _slot("restart_jump")
P_PERSON_HOLD = _slot("person_hold")
P_BACKGROUND_SHIELD = _slot("background_shield")
P_CARRIED_TRAVEL = _slot("carried_travel")
P_CARRIED_RADIUS = _slot("carried_radius")
P_BACKGROUND_TIME = _slot("background_time")
P_BACKGROUND_CELL = _slot("background_cell")
P_BACKGROUND_EXTENT = _slot("background_extent")
P_TAIL_LENGTH = _slot("tail_length")
P_LEG_THRESHOLD = N_PARAMS  # the leg model's threshold, appended by TrackingParams.kernel_vector


# ------------------------------------------------------------------------------------------- context
(
    C_HAS_STAMP,
    C_STAMP,
    C_NEXT_ID,
    C_BG_READY,
    C_BG_COUNT,
    C_BG_SCAN,
    C_BG_X0,
    C_BG_Y0,
    C_BG_LO,
    C_BG_HI,
    C_N_TRACKS,
    C_BG_CACHED,
    C_BG_PX,
    C_BG_PY,
    C_BG_PC,
    C_BG_PS,
    C_CARRY_POSED,
    C_CARRY_PX,
    C_CARRY_PY,
    C_KEPT_N,
    C_KEPT_NEXT,
    C_KEPT_STAMP,
) = range(22)
N_CONTEXT = 22
# C_KEPT_*: the scans kept for the free-space test (_people.keep_scan): how many, the next slot, the last one's stamp
# (ns since the first scan; -1: none yet)
# C_CARRY_*: the sensor position (tracking frame) at the last scan, for the carried beams (_background.carried_update)
# C_BG_CACHED: the background's active cells carry their range and beam as seen from the sensor pose
# (C_BG_PX, C_BG_PY, heading cos/sin C_BG_PC, C_BG_PS); a still sensor need not compute them again


def n_columns(tail_length: int) -> int:
    """Columns of a track table whose tails hold `tail_length` positions (at least one)."""
    return N_FIXED + 2 * max(tail_length, 1)


def new_context() -> np.ndarray:
    """The context of a tracker that has seen no scan (next id 1, no background grid yet)."""
    ctx = np.zeros(N_CONTEXT)
    ctx[C_NEXT_ID] = 1.0
    ctx[C_KEPT_STAMP] = -1.0
    return ctx


class TrackTable:
    """The live tracks of a tracker: `table[:n]` (see the module docstring) with named views."""

    def __init__(self, tail_length: int, capacity: int = 64) -> None:
        self.tail_length = max(tail_length, 1)
        self.table = np.zeros((capacity, n_columns(tail_length)))
        self.n = 0

    def __len__(self) -> int:
        return self.n

    def column(self, c: int) -> np.ndarray:
        """Column `c` of the live tracks (a view)."""
        return self.table[: self.n, c]

    @property
    def id(self) -> np.ndarray:
        return self.table[: self.n, ID].astype(np.int64)

    @property
    def x(self) -> np.ndarray:
        """(n, 4) x, y, vx, vy (a view), tracking frame."""
        return self.table[: self.n, X : X + 4]

    @property
    def P(self) -> np.ndarray:
        """(n, 4, 4) covariances (a copy)."""
        return self.table[: self.n, P0 : P0 + 16].reshape(self.n, 4, 4)

    @property
    def votes(self) -> np.ndarray:
        return self.table[: self.n, VOTES : VOTES + 5].astype(np.int64)

    @property
    def tail(self) -> np.ndarray:
        """(n, T, 2) ring buffers of recent positions (tracking frame, m; a view)."""
        return self.table[: self.n, TAIL : TAIL + 2 * self.tail_length].reshape(self.n, self.tail_length, 2)

    @property
    def tail_count(self) -> np.ndarray:
        """(n,) int64 positions written to each tail so far."""
        return self.table[: self.n, TAIL_COUNT].astype(np.int64)
