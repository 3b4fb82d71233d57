"""Where a virtual LMS200's scans come from: complete scans as uint16 values, as the LMS sends them, for the
variant, units and measuring mode the host set (a log's scans, fixed arrays; datmo_cli.passes.simulated adds a scene)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from . import protocol as P


class ScanSource:
    """Complete scans (uint16 values as the LMS sends them) for a variant, units and measuring mode."""

    def scans(self, angle_deg: int, resolution_cdeg: int, units: str, measuring_mode: int) -> Iterator[np.ndarray]:
        raise NotImplementedError


class ArraySource(ScanSource):
    """Fixed values, repeated: `values` (K, B) uint16 for the variant with B values (others get a wall)."""

    def __init__(self, values: np.ndarray) -> None:
        self.values = np.atleast_2d(np.asarray(values, np.uint16))

    def scans(self, angle_deg, resolution_cdeg, units, measuring_mode):
        n = P.VARIANTS[(angle_deg, resolution_cdeg)]
        rows = self.values if self.values.shape[1] == n else np.full((1, n), 2000, np.uint16)
        while True:
            yield from rows


class LogSource(ScanSource):
    """The scans of a log, repeated; each beam of the variant takes the log's nearest beam (NaN outside)."""

    def __init__(self, path: str | Path) -> None:
        from ..logs.channels import read_run

        self.run = read_run(path)
        self.path = Path(path)
        if self.run.geometry.n_beams == 0:
            raise InputError(f"{path}: its scans have no beams: nothing to serve")

    def scans(self, angle_deg, resolution_cdeg, units, measuring_mode):
        g = self.run.geometry
        n = P.VARIANTS[(angle_deg, resolution_cdeg)]
        want = np.radians(-angle_deg / 2 + resolution_cdeg / 100 * np.arange(n))
        pos = np.rint((want - g.angle_min) / g.angle_increment).astype(np.int64)
        inside = (
            (pos >= 0)
            & (pos < g.n_beams)
            & (np.abs(g.angle_min + pos * g.angle_increment - want) <= abs(g.angle_increment))
        )
        pos = np.clip(pos, 0, g.n_beams - 1)
        ranges = self.run.ranges[:, pos]
        ranges[:, ~inside] = np.nan
        values = P.ranges_to_values(ranges, units, measuring_mode)
        while True:
            yield from values
