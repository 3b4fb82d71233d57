"""The search space of `datmo tune`: a TOML file naming parameters of the configuration tree with a range or
choices, each checked against the parameter's declaration (bounds.param) with the messages of a config file,
and the quasi-random settings drawn from it.

    [track]
    person_maintain = [0.05, 0.3]                   # two numbers: a range (floats, or integers for an integer key)
    confirm_hits = [2, 8]
    delete_after = { range = [0.3, 3.0], log = true }   # sampled evenly in the logarithm
    [features]
    leg_model = ["default", "paper"]                # strings: choices
    min_points = { choices = [3, 5, 8] }            # numbers as choices

Values are in the parameters' own units (bounds.Bound.unit). Samples are a scrambled Sobol sequence
(scipy.stats.qmc) of the seed: the same seed gives the same settings, in the same order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

from ..base.bounds import check
from ..base.errors import ConfigError

ROUND_DIGITS = 4  # significant digits of a sampled float (readable, and written back exactly in best.toml)


@dataclass(frozen=True)
class Dimension:
    """One parameter of the space: `key` ('section.name', its home), a range [lo, hi] (integer: whole numbers;
    log: sampled evenly in the logarithm) or `choices`."""

    key: str
    lo: float = 0.0
    hi: float = 0.0
    integer: bool = False
    log: bool = False
    choices: tuple = ()

    def value(self, u: float) -> object:
        """The value at `u` in [0, 1): a choice, a whole number, or a float rounded to ROUND_DIGITS digits."""
        if self.choices:
            return self.choices[min(int(u * len(self.choices)), len(self.choices) - 1)]
        if self.integer:
            return int(min(self.lo + math.floor(u * (self.hi - self.lo + 1)), self.hi))
        x = self.lo * (self.hi / self.lo) ** u if self.log else self.lo + u * (self.hi - self.lo)
        return min(max(float(f"{x:.{ROUND_DIGITS}g}"), self.lo), self.hi)

    def describe(self) -> str:
        """'range [0.05, 0.3]', 'range [2, 8] (log)' or 'choices default, paper'."""
        if self.choices:
            return "choices " + ", ".join(str(c) for c in self.choices)
        return f"range [{self.lo:g}, {self.hi:g}]" + (" (log)" if self.log else "")

    def spec(self) -> dict:
        """The dimension as plain values (for the tune's record of its settings)."""
        if self.choices:
            return {"key": self.key, "choices": list(self.choices)}
        return {"key": self.key, "range": [self.lo, self.hi], "integer": self.integer, "log": self.log}


def load_space(path: str | Path) -> list[Dimension]:
    """The dimensions of the space file at `path`, in file order; ConfigError in one line naming the file and
    the key (unknown parameter, a range outside its bounds or upside down, an empty list of choices)."""
    from ..passes.config import read_tables

    tables = read_tables(path)  # the tables of a config file: [features], [track] (top-level keys placed)
    dims = [_dimension(str(path), s, k, v) for s, table in tables.items() for k, v in table.items()]
    if not dims:
        raise ConfigError(f"{path}: no parameters; name at least one, e.g. [track] person_maintain = [0.05, 0.3]")
    seen: set[str] = set()
    for d in dims:
        if d.key in seen:
            raise ConfigError(f"{path}: {d.key}: given twice (once in its home section, once elsewhere)")
        seen.add(d.key)
    return dims


def _dimension(path: str, section: str, key: str, spec: object) -> Dimension:
    """One dimension from space file `path`'s `key = spec` in `section` (messages as bounds.validate's)."""
    from ..passes.config import SECTIONS

    cls = SECTIONS[section]
    name = f"{path}: {section}.{key}"
    if key in cls.renamed:
        raise ConfigError(f"{name}: renamed to {cls.renamed[key]}")
    if key in cls.removed:
        raise ConfigError(f"{name}: no longer a parameter: {cls.removed[key]}")
    known = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    if key not in known:
        raise ConfigError(f"{name}: unknown parameter (known: {', '.join(sorted(known))})")
    meta = known[key].metadata
    if meta.get("same_as"):  # a parameter whose home is another section: tuned there
        home, _, home_key = meta["same_as"].partition(".")
        return _dimension(path, home, home_key, spec)
    full = f"{section}.{key}"
    log = False
    if isinstance(spec, dict):
        extra = set(spec) - {"range", "choices", "log"}
        if extra or ("range" in spec) == ("choices" in spec):
            raise ConfigError(f"{name}: give {{ range = [LOW, HIGH] }} or {{ choices = [...] }}, got {spec!r}")
        log = spec.get("log", False)
        if not isinstance(log, bool):
            raise ConfigError(f"{name}: log must be true or false, got {log!r}")
        if "choices" in spec:
            return Dimension(full, choices=_choices(name, meta, spec["choices"], full))
        spec = spec["range"]
        if not (isinstance(spec, list) and len(spec) == 2):
            raise ConfigError(f"{name}: a range is two numbers [LOW, HIGH], got {spec!r}")
    if not isinstance(spec, list):
        raise ConfigError(f"{name}: give a range [LOW, HIGH] or a list of choices, got {spec!r}")
    bound = meta["bound"]
    if bound is None or len(spec) != 2 or any(isinstance(v, str) for v in spec):
        return Dimension(full, choices=_choices(name, meta, spec, full))
    lo, hi = (check(bound, v, name) for v in spec)
    if not lo < hi:
        raise ConfigError(f"{name}: a range's low end must be below its high end, got [{lo:g}, {hi:g}]")
    if log and not lo > 0:
        raise ConfigError(f"{name}: a log range must start above 0, got [{lo:g}, {hi:g}]")
    return Dimension(full, lo, hi, integer=bound.integer, log=log)


def _choices(name: str, meta, values: object, key: str) -> tuple:
    """The choices of dimension `key`, each a value the parameter takes (messages as bounds.validate's; a leg
    model must load, as datmo run checks before any input)."""
    if not isinstance(values, list) or not values:
        raise ConfigError(f"{name}: an empty list of choices; give at least one value")
    out: list[object] = []
    for v in values:
        if meta["bound"] is not None:
            out.append(check(meta["bound"], v, name))
        elif meta["choices"]:
            if v not in meta["choices"]:
                raise ConfigError(f"{name}: one of {', '.join(meta['choices'])}; got {v!r}")
            out.append(v)
        elif not isinstance(v, str) or not v.strip():
            raise ConfigError(f"{name}: must be a non-empty string, got {v!r}")
        else:
            out.append(v)
    if len(set(out)) != len(out):
        raise ConfigError(f"{name}: a choice is given twice in {values!r}")
    if key == "features.leg_model":
        from ..base.errors import DatmoError
        from ..perception.leg_model import load_leg_model

        for v in out:
            try:
                load_leg_model(str(v))
            except DatmoError as exc:
                raise ConfigError(f"{name}: {exc}") from None
    return tuple(out)


def samples(dims: list[Dimension], n: int, seed: int) -> list[dict[str, object]]:
    """`n` settings ({key: value}) of the space: the first `n` points of the scrambled Sobol sequence of `seed`
    (scipy.stats.qmc), each coordinate mapped by its dimension."""
    from scipy.stats import qmc

    if n <= 0:
        return []
    m = max(math.ceil(math.log2(n)), 0)
    points = qmc.Sobol(len(dims), scramble=True, seed=seed).random_base2(m)[:n]
    return [{d.key: d.value(float(u)) for d, u in zip(dims, row, strict=True)} for row in points]
