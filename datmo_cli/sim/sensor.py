"""The SICK LMS200 as a measuring instrument: beam layout, range modes, noise and output quantisation.

The sensor reports integer distances (docs/lms2xx.md §6): mm with 13, 14 or 15 distance bits for the
8, 16 and 32 m modes, cm with 13 bits for the 80 m mode. Values from ...F7 up are codes: ...F7 "greater
than maximum" (stored as +inf), the others (...FF no return, ...FE dazzle, ...) as NaN. Here a beam
that hits nothing, or hits beyond the mode's reach, reports ...F7; a dropped return reports ...FF.
With cm units in the 8, 16 or 32 m modes, anything beyond the nominal range reports ...F7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..logs.scan import ScanGeometry

FIELDS_OF_VIEW = {180: (1.0, 0.5), 100: (1.0, 0.5, 0.25)}  # degrees -> allowed resolutions, degrees
MAX_RATE_HZ = {1.0: 75.0, 0.5: 37.5, 0.25: 18.75}  # one mirror turn per 1° grid (TL p.19)
RANGE_BITS = {8: 13, 16: 14, 32: 15, 80: 13}
UNITS_M = {"mm": 0.001, "cm": 0.01}


@dataclass(frozen=True)
class Sensor:
    """LMS200 settings: field of view and resolution in degrees, range mode in metres, noise sigma in metres,
    dropout as the probability that a beam returns nothing, rate in Hz."""

    fov_deg: int = 180
    resolution_deg: float = 0.5
    range_mode_m: int = 8
    units: str = "mm"
    noise_sigma: float = 0.01
    rate_hz: float = 5.0
    dropout: float = 0.0

    def __post_init__(self) -> None:
        if self.fov_deg not in FIELDS_OF_VIEW:
            raise ValueError(f"field of view must be 180 or 100 degrees, got {self.fov_deg}")
        if self.resolution_deg not in FIELDS_OF_VIEW[self.fov_deg]:
            allowed = ", ".join(f"{r:g}" for r in FIELDS_OF_VIEW[self.fov_deg])
            raise ValueError(
                f"resolution {self.resolution_deg:g}° is not available at {self.fov_deg}° (choose {allowed})"
            )
        if self.range_mode_m not in RANGE_BITS:
            raise ValueError(f"range mode must be 8, 16, 32 or 80 m, got {self.range_mode_m}")
        if self.units not in UNITS_M:
            raise ValueError(f"units must be mm or cm, got {self.units!r}")
        if self.range_mode_m == 80 and self.units != "cm":
            raise ValueError("the 80 m range mode reports in cm (use units cm)")
        if not (self.noise_sigma >= 0 and np.isfinite(self.noise_sigma)):
            raise ValueError(f"noise sigma must be a finite number >= 0, got {self.noise_sigma}")
        if not 0 <= self.dropout < 1:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        top = MAX_RATE_HZ[self.resolution_deg]
        if not 0 < self.rate_hz <= top:
            raise ValueError(
                f"rate must be above 0 and at most {top:g} Hz at {self.resolution_deg:g}°, got {self.rate_hz:g}"
            )

    @property
    def n_beams(self) -> int:
        return int(round(self.fov_deg / self.resolution_deg)) + 1

    @property
    def unit_m(self) -> float:
        return UNITS_M[self.units]

    @property
    def code_greater_than_max(self) -> int:
        """The ...F7 code of this mode's distance bits."""
        return (1 << RANGE_BITS[self.range_mode_m]) - 9

    @property
    def code_no_return(self) -> int:
        return (1 << RANGE_BITS[self.range_mode_m]) - 1

    @property
    def reach_m(self) -> float:
        """Farthest distance reported as a number, m."""
        bits_reach = (self.code_greater_than_max - 0.5) * self.unit_m
        return bits_reach if self.units == "mm" else min(bits_reach, float(self.range_mode_m))

    def angles(self) -> np.ndarray:
        """Beam angles (B,), radians, sensor frame, counter-clockwise from x (forward), -fov/2 first."""
        return np.radians(-self.fov_deg / 2 + self.resolution_deg * np.arange(self.n_beams))

    def geometry(self, frame_id: str = "laser") -> ScanGeometry:
        """The LaserScan geometry: nominal range limits, all beams measured at the scan's instant."""
        return ScanGeometry(
            angle_min=float(np.radians(-self.fov_deg / 2)),
            angle_increment=float(np.radians(self.resolution_deg)),
            n_beams=self.n_beams,
            range_min=0.0,
            range_max=float(self.range_mode_m),
            time_increment=0.0,
            scan_time=1.0 / self.rate_hz,
            frame_id=frame_id,
        )

    def measure(self, distances: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The integer values (uint16) the sensor sends for true distances (m; inf: no target).

        Gaussian noise of sigma `noise_sigma` is added before rounding to the unit.
        """
        d = np.asarray(distances, np.float64)
        noise = rng.standard_normal(d.shape) * self.noise_sigma
        with np.errstate(invalid="ignore"):
            r = np.maximum(d + noise, 0.0)
            q = np.rint(r / self.unit_m)
            far = ~(r < self.reach_m) | ~(q < self.code_greater_than_max)
            q[far] = 0.0
        codes = np.where(far, self.code_greater_than_max, q).astype(np.uint16)
        if self.dropout > 0:
            codes[rng.random(d.shape) < self.dropout] = self.code_no_return
        return codes

    def ranges(self, codes: np.ndarray) -> np.ndarray:
        """Ranges (float32, m) of sensor values: ...F7 -> +inf, other codes -> NaN (as the drivers store them)."""
        codes = np.asarray(codes)
        top = self.code_greater_than_max
        out = (codes.astype(np.float64) * self.unit_m).astype(np.float32)
        out[codes == top] = np.inf
        out[codes > top] = np.nan
        return out


NO_RETURN_CODE = 0xFFFF  # Scanner: nothing within range_max
ERROR_CODE = 0  # Scanner: a dropped return, or a target nearer than range_min


@dataclass(frozen=True)
class Scanner:
    """A scanner other than the LMS200, as a scene's [scanner] table gives it (a Hokuyo-like one): `n_beams`
    beams `fov_deg / n_beams` degrees apart from -fov_deg/2 (counter-clockwise, as Hokuyo drivers lay them
    out: the last beam is one step short of +fov_deg/2), ranges from `range_min` to `range_max` metres sent as
    whole millimetres, Gaussian noise of sigma `noise_sigma` m, `rate_hz` scans per second, and `dropout`, the
    probability that a beam returns nothing. A beam that hits nothing within range_max reads +inf; a dropped
    one, or one nearer than range_min, NaN."""

    n_beams: int = 768
    fov_deg: float = 270.0
    range_min: float = 0.02
    range_max: float = 10.0
    noise_sigma: float = 0.01
    rate_hz: float = 10.0
    dropout: float = 0.0

    def __post_init__(self) -> None:
        if not 2 <= self.n_beams <= 10_000:
            raise ValueError(f"beams must be 2 to 10000, got {self.n_beams}")
        if not 0 < self.fov_deg <= 360:
            raise ValueError(f"field of view must be in (0, 360] degrees, got {self.fov_deg:g}")
        if not 0 <= self.range_min < self.range_max <= 60:
            raise ValueError(
                f"range must be [min, max] with 0 <= min < max <= 60 m, got [{self.range_min:g}, {self.range_max:g}]"
            )
        if not (self.noise_sigma >= 0 and np.isfinite(self.noise_sigma)):
            raise ValueError(f"noise sigma must be a finite number >= 0, got {self.noise_sigma}")
        if not 0 <= self.dropout < 1:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        if not 0 < self.rate_hz <= 75:
            raise ValueError(f"rate must be above 0 and at most 75 Hz, got {self.rate_hz:g}")

    @property
    def resolution_deg(self) -> float:
        return self.fov_deg / self.n_beams

    def angles(self) -> np.ndarray:
        """Beam angles (B,), radians, sensor frame, counter-clockwise from x (forward), -fov/2 first."""
        return np.radians(-self.fov_deg / 2) + np.radians(self.resolution_deg) * np.arange(self.n_beams)

    def geometry(self, frame_id: str = "laser") -> ScanGeometry:
        return ScanGeometry(
            angle_min=float(np.radians(-self.fov_deg / 2)),
            angle_increment=float(np.radians(self.resolution_deg)),
            n_beams=self.n_beams,
            range_min=float(self.range_min),
            range_max=float(self.range_max),
            time_increment=0.0,
            scan_time=1.0 / self.rate_hz,
            frame_id=frame_id,
        )

    def measure(self, distances: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Whole millimetres (uint16) for true distances (m; inf: no target): NO_RETURN_CODE beyond range_max,
        ERROR_CODE nearer than range_min and for dropped returns. Noise is added before rounding."""
        d = np.asarray(distances, np.float64)
        noise = rng.standard_normal(d.shape) * self.noise_sigma
        with np.errstate(invalid="ignore"):
            r = np.maximum(d + noise, 0.0)
            far = ~(r < self.range_max)
            near = r < self.range_min
            q = np.where(far | near, 0.0, np.rint(r * 1000.0))
        codes = np.where(far, NO_RETURN_CODE, np.where(near, ERROR_CODE, np.maximum(q, 1))).astype(np.uint16)
        if self.dropout > 0:
            codes[rng.random(d.shape) < self.dropout] = ERROR_CODE
        return codes

    def ranges(self, codes: np.ndarray) -> np.ndarray:
        """Ranges (float32, m) of codes: NO_RETURN_CODE -> +inf, ERROR_CODE -> NaN."""
        codes = np.asarray(codes)
        out = (codes.astype(np.float64) * 0.001).astype(np.float32)
        out[codes == NO_RETURN_CODE] = np.inf
        out[codes == ERROR_CODE] = np.nan
        return out
