"""Reading a scene's TOML tables (sim/scene.py): typed, checked fields (numbers, bounded numbers, vectors, points,
paths in metres, metres per second and seconds) whose errors name the file, the table and the key."""

from __future__ import annotations

from typing import NoReturn

import numpy as np

from ..base.bounds import Bound, check
from ..base.errors import ConfigError
from .paths import PathSpec

PATH_KEYS = {"path", "speed", "pauses", "start_time", "loop"}

_REQUIRED = object()


class SceneValidator:
    """Typed getters that raise ConfigError naming the file, table and key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, key: str, msg: str) -> NoReturn:
        raise ConfigError(f"{self.source}: {where}, key '{key}': {msg}")

    def keys(self, t: dict, where: str, allowed: set[str]) -> None:
        for k in t:
            if k not in allowed:
                raise ConfigError(f"{self.source}: {where}: unknown key '{k}' (allowed: {', '.join(sorted(allowed))})")

    def _get(self, t: dict, where: str, key: str, default):
        if key not in t:
            if default is _REQUIRED:
                raise ConfigError(f"{self.source}: {where}: missing key '{key}'")
            return _REQUIRED
        return t[key]

    def table(self, data: dict, key: str, where: str) -> dict:
        t = data[key]
        if not isinstance(t, dict):
            raise ConfigError(f"{self.source}: '{key}' must be a table ({where})")
        return t

    def tables(self, data: dict, key: str) -> list[tuple[dict, str]]:
        items = data.get(key, [])
        if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
            raise ConfigError(f"{self.source}: '{key}' must be an array of tables ([[{key}]])")
        return [(t, f"[[{key}]] {i}") for i, t in enumerate(items, 1)]

    def string(self, t: dict, where: str, key: str, default=_REQUIRED):
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return default
        if not isinstance(x, str):
            self.fail(where, key, f"must be a string, got {x!r}")
        return x

    def boolean(self, t: dict, where: str, key: str, default=_REQUIRED) -> bool:
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return default
        if not isinstance(x, bool):
            self.fail(where, key, f"must be true or false, got {x!r}")
        return x

    def integer(self, t: dict, where: str, key: str, default=_REQUIRED) -> int:
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return default
        if isinstance(x, bool) or not isinstance(x, int) or x < 0:
            self.fail(where, key, f"must be a whole number >= 0, got {x!r}")
        return x

    def number(
        self, t: dict, where: str, key: str, default=_REQUIRED, *, positive: bool = False, nonnegative: bool = False
    ):
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return default
        if isinstance(x, bool) or not isinstance(x, int | float) or not np.isfinite(x):
            self.fail(where, key, f"must be a number, got {x!r}")
        if positive and x <= 0:
            self.fail(where, key, f"must be > 0, got {x!r}")
        if nonnegative and x < 0:
            self.fail(where, key, f"must be >= 0, got {x!r}")
        return float(x)

    def bounded(self, t: dict, where: str, key: str, default: float, bound: Bound) -> float | int:
        """A number within `bound` (bounds.py), its range said in the error."""
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return default
        return check(bound, x, f"{self.source}: {where}, key '{key}'")

    def vector(self, t: dict, where: str, key: str, n: int, default=_REQUIRED):
        x = self._get(t, where, key, default)
        if x is _REQUIRED:
            return None if default is None else np.array(default, np.float64)
        if (
            not isinstance(x, list)
            or len(x) != n
            or not all(isinstance(c, int | float) and not isinstance(c, bool) and np.isfinite(c) for c in x)
        ):
            self.fail(where, key, f"must be a list of {n} numbers, got {x!r}")
        return np.array(x, np.float64)

    def points(self, t: dict, where: str, key: str, minimum: int = 1) -> np.ndarray:
        x = self._get(t, where, key, _REQUIRED)
        ok = (
            isinstance(x, list)
            and len(x) >= minimum
            and all(
                isinstance(p, list)
                and len(p) == 2
                and all(isinstance(c, int | float) and not isinstance(c, bool) and np.isfinite(c) for c in p)
                for p in x
            )
        )
        if not ok:
            self.fail(where, key, f"must be a list of {minimum} or more [x, y] points, got {x!r}")
        return np.array(x, np.float64)

    def path(self, t: dict, where: str, required: bool = True) -> PathSpec | None:
        if "path" not in t:
            if required:
                raise ConfigError(f"{self.source}: {where}: missing key 'path'")
            for k in PATH_KEYS - {"path"}:
                if k in t:
                    self.fail(where, k, "only applies with a 'path'")
            return None
        pts = self.points(t, where, "path", minimum=2)
        loop = self.boolean(t, where, "loop", False)
        seq = np.vstack([pts, pts[:1]]) if loop else pts
        if np.any(np.all(np.diff(seq, axis=0) == 0, axis=1)):
            self.fail(where, "path", "two consecutive waypoints are equal")
        pauses_raw = t.get("pauses", [])
        pauses: dict[int, float] = {}
        if not isinstance(pauses_raw, list):
            self.fail(where, "pauses", "must be a list of [waypoint index, seconds] pairs")
        for p in pauses_raw:
            if (
                not isinstance(p, list)
                or len(p) != 2
                or isinstance(p[0], bool)
                or not isinstance(p[0], int)
                or not 0 <= p[0] < len(pts)
                or isinstance(p[1], bool)
                or not isinstance(p[1], int | float)
                or not 0 <= p[1] < np.inf
            ):
                self.fail(where, "pauses", f"each pause is [waypoint index 0..{len(pts) - 1}, seconds >= 0], got {p!r}")
            pauses[int(p[0])] = float(p[1])
        return PathSpec(
            pts,
            self.number(t, where, "speed", 1.0, positive=True),
            pauses,
            self.number(t, where, "start_time", 0.0, nonnegative=True),
            loop,
        )
