"""The compiled tracking step: one numba call tracks a scan, or a block of scans, on the track table.

Every phase of Tracker.step (tracker.py's docstring has the rules) runs here on the table of state.py, in
this order: features to measurements (_scan_measurements), moved to the tracking frame, leg candidates on the
background or carried taken out (_background), legs given to the tracks of people (_people), prediction, gating
and global nearest neighbour, Kalman update and reacquisition of tracks lost while occluded (_association), leg
evidence (_people), occlusion, life cycle and duplicates, new tracks (_life_cycle), classification (_classify),
tails, the background grid, and the Track elements out. tests/reference_tracking.py holds the same rules as
numpy statements; tests/test_tracking_step.py checks the two agree, phase by phase and over whole logs.

Frames: measurements arrive in the sensor frame (x forward, y left, m); tracks live in the tracking frame
(the world frame when a pose (x, y, theta) is given, else the sensor frame); the Track elements out carry
sensor-frame positions and velocities and, with a pose, world ones. Times: ns since the tracker's first
scan (int64), seconds for durations. Kinds: measurements.KIND_*; classes and mobility: datmo_msgs/Track's.

What travels together is one tuple (the named ones are bundles.py's, read by field):
    meas       a scan's measurements, bundles.ScanMeasurements (x, y, size (M,) m, kind (M,) int64, legs (M, 4) m,
               raw (L, RAW_COLS) leg candidates, prob (M,) leg probability)
    features   a block's features, bundles.FeatureBlock (per kind flat over the scans, with per-scan offsets)
    sensor     (ranges (B,) float32 m, has_ranges, has_pose, pose (x, y m, theta rad), geo: angle_min, increment
               (rad), range_max, has geometry, range_min (m))
    beam_dirs  (cos, sin) of each beam's angle (B,)
    bg         the background grid (score, mark, active, cache); see _background.py
    carry      the beams' memory: the carried beams (ref, seen, away; see _background.py), then the scans kept for the
               free-space test (ranges (K, B) float32 m, poses (K, 3) tracking frame; see _people.keep_scan)
    rules      (learned: with a leg detector, compat (6, N_KINDS): the kinds a track may take by its kind group,
               reacq (6, N_KINDS): the kinds it may be reacquired on)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ._association import associate, kind_group, merge_reacquired, predict, reacquire, update
from ._background import background, carried_update, hit_background, off_background
from ._classify import classify
from ._life_cycle import life_cycle, occlusion, push_tail, spawn
from ._people import free_legs, keep_scan, leg_evidence, legs_stage
from ._scan_measurements import learned_measurements, moved, paper_measurements, to_sensor
from .bundles import Blobs, Circles, Legs, Lines, ScanMeasurements
from .state import (
    AGE,
    C_HAS_STAMP,
    C_N_TRACKS,
    C_STAMP,
    CLS,
    CONFIRMED,
    HIT,
    HITS,
    ID,
    IS_PERSON,
    MISSES,
    MOBILITY,
    OCCLUDED,
    P0,
    P_TAIL_LENGTH,
    SIZE,
    TAIL,
    TAIL_COUNT,
    VX,
    VY,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

ANY_ROW = 4  # the compatibility row of tentative tracks (tracker._COMPAT)


# -------------------------------------------------------------------------------------------- the step
@njit(cache=True)
def track_scan(tab, ctx, prm, stamp, meas, has_prob, sensor, beam_dirs, bg, carry, rules):
    """One scan (measurements meas in the sensor frame, stamp in ns since the first scan) through every phase
    (tuples: the module's docstring); returns the table (a new one when it grew). ctx[C_N_TRACKS] holds the
    number of live tracks."""
    ranges, has_ranges, has_pose, pose, geo = sensor
    learned, compat, reacq = rules
    n = int(ctx[C_N_TRACKS])
    dt = max((stamp - np.int64(ctx[C_STAMP])) * 1e-9, 0.0) if ctx[C_HAS_STAMP] != 0 else 0.0
    ctx[C_HAS_STAMP], ctx[C_STAMP] = 1.0, stamp
    if has_pose:
        px, py, pc, ps = pose[0], pose[1], np.cos(pose[2]), np.sin(pose[2])
        x, y, legs, raw = moved(meas.x, meas.y, meas.legs, meas.raw, px, py, pc, ps)
        meas = ScanMeasurements(x, y, meas.size, meas.kind, legs, raw, meas.prob)
    else:
        px, py, pc, ps = 0.0, 0.0, 1.0, 0.0
    frame = (px, py, pc, ps)
    crow = np.empty(n, np.int64)
    for k in range(n):
        crow[k] = kind_group(tab, k) if tab[k, CONFIRMED] != 0 else ANY_ROW
    predict(tab, n, dt, prm)
    carried_update(carry[0], carry[1], carry[2], ranges, has_ranges, has_pose, pose, geo, ctx, prm)
    found = off_background(tab, n, meas, bg[0], ctx, frame, sensor, carry, prm)
    scan, rows0 = legs_stage(tab, n, found, prm)  # the measurements the tracks take
    mx, my, mkind, mlegs = scan.x, scan.y, scan.kind, scan.legs
    rows, cols = associate(tab, n, mx, my, mkind, scan.prob, scan.raw, rows0, compat, crow, prm)
    hit_background(tab, n, rows, cols, scan, bg[0], ctx, frame, prm)
    update(tab, n, rows, cols, mx, my, mkind, scan.size, mlegs, prm)
    rows2, cols2 = reacquire(tab, n, rows, cols, mx, my, mkind, stamp, reacq, crow, prm)
    rows, cols, superseded = merge_reacquired(rows, cols, rows2, cols2)
    leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, scan.prob, scan.raw, has_prob, prm)
    free_legs(tab, rows, cols, mx, my, mkind, mlegs, (carry[3], carry[4]), geo, ctx, prm)
    occlusion(tab, n, ranges, has_ranges, geo, has_pose, pose, prm)
    n = life_cycle(tab, n, stamp, superseded, learned, prm)
    tab, n = spawn(tab, n, cols, scan, has_prob, stamp, ctx, prm)
    classify(tab, n, dt, stamp, learned, prm)
    push_tail(tab, n, prm)
    background(bg, ctx, sensor, beam_dirs, frame, dt, tab, n, prm)
    keep_scan(carry[3], carry[4], ranges, has_ranges and geo[3] != 0, pose, stamp, ctx, prm)
    ctx[C_N_TRACKS] = n
    return tab


@njit(cache=True)
def step_measurements(tab, ctx, prm, stamp, meas, has_prob, sensor, beam_dirs, bg, carry, rules, out):
    """track_scan on one scan's measurements, then its live tracks as Track elements in `out` (a new, larger
    array when it is too small). Returns (table, out)."""
    tab = track_scan(tab, ctx, prm, stamp, meas, has_prob, sensor, beam_dirs, bg, carry, rules)
    n = int(ctx[C_N_TRACKS])
    if n > len(out):
        out = np.empty(2 * n, out.dtype)
    write_tracks(out, 0, tab, n, sensor[2], sensor[3])
    return tab, out


@njit(cache=True, nogil=True)
def track_block(tab, ctx, prm, scans, features, geo, beam_dirs, bg, carry, rules, output):
    """Track scans 0..len(stamps)-1 of a block of features (flat per kind, with per-scan offsets) in one call.

    scans: (stamps (N,) ns since the first scan, ranges (N, B) float32 m, has_ranges, poses (N, 3), has_pose);
    features: bundles.FeatureBlock (circles, blobs, lines, legs flat over the scans, sensor frame, m, beam indices
    inclusive; scan i's are items offsets.<kind>[i]:offsets.<kind>[i + 1]). geo, beam_dirs, bg, carry, rules: as
    track_scan's (module docstring). output: (out, tails, out_tail, out_tail_count, offsets). Writes the live
    tracks of scan i to out[offsets[i]:offsets[i + 1]] and, when `tails`, their tails (tracking frame) to out_tail
    and tail counts to out_tail_count (each grown when full). Returns (table, out, out_tail, out_tail_count)."""
    stamps, ranges, has_ranges, poses, has_pose = scans
    out, tails, out_tail, out_tail_count, offsets = output
    learned = rules[0]
    T = int(prm[P_TAIL_LENGTH])
    at, fc, fb, fl, fg = features.offsets, features.circles, features.blobs, features.lines, features.legs
    offsets[0] = 0
    for i in range(len(stamps)):
        a, b = at.circles[i], at.circles[i + 1]
        circles = Circles(fc.first[a:b], fc.last[a:b], fc.x[a:b], fc.y[a:b], fc.radius[a:b])
        a, b = at.blobs[i], at.blobs[i + 1]
        blobs = Blobs(fb.first[a:b], fb.last[a:b], fb.x[a:b], fb.y[a:b], fb.size[a:b], fb.kind[a:b])
        a, b = at.lines[i], at.lines[i + 1]
        lines = Lines(
            fl.segment[a:b], fl.first[a:b], fl.last[a:b], fl.x_ini[a:b], fl.y_ini[a:b], fl.x_end[a:b], fl.y_end[a:b]
        )
        a, b = at.legs[i], at.legs[i + 1]
        legs = Legs(fg.first[a:b], fg.last[a:b], fg.x[a:b], fg.y[a:b], fg.width[a:b], fg.probability[a:b])
        if learned:
            meas = learned_measurements(circles, blobs, lines, legs, prm)
        else:
            meas = paper_measurements(circles, blobs, lines, prm)
        sensor = (ranges[i], has_ranges, has_pose, poses[i], geo)
        tab = track_scan(tab, ctx, prm, stamps[i], meas, learned, sensor, beam_dirs, bg, carry, rules)
        n = int(ctx[C_N_TRACKS])
        o = offsets[i]
        if o + n > len(out):
            size = max(2 * len(out), o + n)
            grown = np.empty(size, out.dtype)
            grown[:o] = out[:o]
            out = grown
            if tails:
                gt = np.empty((size, T, 2))
                gt[:o] = out_tail[:o]
                out_tail = gt
                gc = np.empty(size, np.int64)
                gc[:o] = out_tail_count[:o]
                out_tail_count = gc
        write_tracks(out, o, tab, n, has_pose, poses[i])
        if tails:
            for k in range(n):
                for t in range(T):
                    out_tail[o + k, t, 0] = tab[k, TAIL + 2 * t]
                    out_tail[o + k, t, 1] = tab[k, TAIL + 2 * t + 1]
                out_tail_count[o + k] = np.int64(tab[k, TAIL_COUNT])
        offsets[i + 1] = o + n
    return tab, out, out_tail, out_tail_count


@njit(cache=True)
def write_tracks(out, o, tab, n, has_pose, pose):
    """Track elements of tracks 0..n-1 into out[o:o + n] (tracker.output). Fields by r["name"], which numba
    compiles as r.name and plain Python (NUMBA_DISABLE_JIT=1) understands on a numpy record."""
    c, s = (np.cos(pose[2]), np.sin(pose[2])) if has_pose else (1.0, 0.0)
    for k in range(n):
        r = out[o + k]
        r["id"] = np.uint32(tab[k, ID])
        r["age"] = np.uint32(tab[k, AGE])
        r["hits"] = np.uint32(tab[k, HITS])
        r["misses"] = np.uint32(tab[k, MISSES])
        sx, sy = to_sensor(tab[k, X], tab[k, Y], has_pose, pose)
        r["x"], r["y"] = sx, sy
        if has_pose:
            r["vx"] = c * tab[k, VX] + s * tab[k, VY]
            r["vy"] = -s * tab[k, VX] + c * tab[k, VY]
            r["world_x"], r["world_y"], r["world_vx"], r["world_vy"] = tab[k, X], tab[k, Y], tab[k, VX], tab[k, VY]
        else:
            r["vx"], r["vy"] = tab[k, VX], tab[k, VY]
            r["world_x"] = r["world_y"] = r["world_vx"] = r["world_vy"] = np.nan
        for i in range(16):
            r["covariance"][i] = tab[k, P0 + i]
        r["size"] = tab[k, SIZE]
        r["classification"] = np.uint8(tab[k, CLS])
        r["mobility"] = np.uint8(tab[k, MOBILITY])
        confirmed, hit = tab[k, CONFIRMED] != 0, tab[k, HIT] != 0
        r["status"] = np.uint8((1 if hit else 2) if confirmed else 0)
        coasting_person = confirmed and not hit and tab[k, IS_PERSON] != 0
        r["occluded"] = np.uint8(1 if tab[k, OCCLUDED] != 0 or coasting_person else 0)
