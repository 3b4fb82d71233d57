"""ScanFeatures from plain lists of circles, lines, blobs and legs: the scenes of the tracking tests and the
ideal features of benchmarks/tracking_scoring.py, without segmentation or feature extraction. Sensor frame, metres."""

from __future__ import annotations

import numpy as np

from datmo_cli.logs import cdr, types
from datmo_cli.tracking.measurements import ScanFeatures

LINE_DTYPE = cdr.element_dtype(types.LINE)
CIRCLE_DTYPE = cdr.element_dtype(types.CIRCLE)
BLOB_DTYPE = cdr.element_dtype(types.BLOB)
LEG_DTYPE = cdr.element_dtype(types.LEG)


def features_from_lists(scans: list[dict]) -> list[ScanFeatures]:
    """ScanFeatures from plain lists, for tests and scripts: each scan a dict with optional "circles"
    [(x, y, radius)], "lines" [(x_ini, y_ini, x_end, y_end)] (each its own segment), "blobs" [(x, y, size)]
    and "legs" [(x, y, width)] (a leg detector's legs, each its own segment)."""
    out = []
    for s in scans:
        c = np.zeros(len(s.get("circles", ())), CIRCLE_DTYPE)
        for k, (x, y, r) in enumerate(s.get("circles", ())):
            c[k]["x"], c[k]["y"], c[k]["radius"], c[k]["segment"] = x, y, r, k
            c[k]["first"], c[k]["last"] = 10 * k, 10 * k + 5  # each its own beams
        li = np.zeros(len(s.get("lines", ())), LINE_DTYPE)
        for k, (x0, y0, x1, y1) in enumerate(s.get("lines", ())):
            li[k]["x_ini"], li[k]["y_ini"], li[k]["x_end"], li[k]["y_end"] = x0, y0, x1, y1
            li[k]["length"], li[k]["segment"] = np.hypot(x1 - x0, y1 - y0), 100 + k
            li[k]["first"], li[k]["last"] = 10 * (100 + k), 10 * (100 + k) + 5
        b = np.zeros(len(s.get("blobs", ())), BLOB_DTYPE)
        for k, (x, y, size) in enumerate(s.get("blobs", ())):
            b[k]["x"], b[k]["y"], b[k]["size"], b[k]["segment"] = x, y, size, 200 + k
            b[k]["first"], b[k]["last"] = 10 * (200 + k), 10 * (200 + k) + 5
        g = np.zeros(len(s.get("legs", ())), LEG_DTYPE)
        for k, (x, y, width) in enumerate(s.get("legs", ())):
            g[k]["x"], g[k]["y"], g[k]["width"], g[k]["segment"], g[k]["probability"] = x, y, width, 300 + k, 1.0
            g[k]["first"], g[k]["last"] = 10 * (300 + k), 10 * (300 + k) + 5
        out.append(ScanFeatures(li, c, b, g))
    return out
