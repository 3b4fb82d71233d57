"""What `datmo tune` optimises: a figure `datmo evaluate` prints, per log, averaged over the logs; and the
constraints a setting must meet (`--max NAME=VALUE`, `--min NAME=VALUE`) on the same averages.

Names: every overall figure of evaluate (`mota`, `hota`, `idf1`, `motp` in metres, `num_switches`, ...), the
same of one class prefixed `people_`, `circle_` or `rect_` (`people_mota`, `people_idf1`: person targets
against person tracks), and rates per second of log: `false_positives_s`, `false_people_s` (false positives
of the person class), `switches_s`. A figure evaluate leaves undefined (HOTA of a log with no mover and no
track) is left out of the mean; a class absent from a log scores nothing there.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..base.errors import ConfigError

CLASS_PREFIXES = {"people": "person", "circle": "circle object", "rect": "rectangular object"}
RATES = {"false_positives_s": (None, "num_false_positives"), "false_people_s": ("person", "num_false_positives")}
RATES["switches_s"] = (None, "num_switches")
# figures shown for each log of a trial (with the objective and the constraints)
SHOWN = ("hota", "mota", "idf1", "motp", "num_switches", "false_positives_s", "people_mota", "false_people_s")


def _base_metrics() -> list[str]:
    from ..evaluate.scoring import HOTA_METRICS, METRICS

    return [*METRICS, *HOTA_METRICS]


def names() -> list[str]:
    """Every name an objective or a constraint can take."""
    base = _base_metrics()
    return base + [f"{p}_{m}" for p in CLASS_PREFIXES for m in base] + list(RATES)


def higher_is_better(name: str) -> bool:
    """Whether a rise of figure `name` means a better tracker (evaluate.HIGHER_IS_BETTER; rates: no)."""
    from ..evaluate.scoring import HIGHER_IS_BETTER

    if name in RATES:
        return False
    base = name.split("_", 1)[1] if name.split("_", 1)[0] in CLASS_PREFIXES else name
    return base in HIGHER_IS_BETTER


def check_name(name: str, option: str) -> str:
    """`name` when it is a figure's name, else ConfigError naming `option` and a near name."""
    import difflib

    known = names()
    if name in known:
        return name
    near = difflib.get_close_matches(name, known, 3)
    hint = f"; did you mean {', '.join(near)}?" if near else f"; e.g. {', '.join(SHOWN)}"
    raise ConfigError(f"{option} {name}: not a figure datmo evaluate prints{hint}")


def log_metrics(scores: dict, seconds: float) -> dict[str, float | int | None]:
    """Every named figure of one log from evaluate's scores (`seconds`: the log's duration, for the rates)."""
    base = _base_metrics()
    out: dict[str, float | int | None] = {m: scores["all"].get(m) for m in base}
    for prefix, name in CLASS_PREFIXES.items():
        of_class = scores.get(name)
        out |= {f"{prefix}_{m}": (of_class.get(m) if of_class else None) for m in base}
    for rate, (cls, count) in RATES.items():
        row: dict = scores["all"] if cls is None else scores.get(cls, {})
        out[rate] = (row.get(count, 0) or 0) / seconds if seconds > 0 else None
    return out


def mean(values: list[float | int | None]) -> float | None:
    """The mean of the defined values (None when none is)."""
    kept = [float(v) for v in values if v is not None]
    return sum(kept) / len(kept) if kept else None


@dataclass(frozen=True)
class Constraint:
    """The mean of figure `name` over the logs must be at most (`upper`) or at least `value`."""

    name: str
    value: float
    upper: bool

    def met(self, value: float | None) -> bool:
        return value is not None and (value <= self.value if self.upper else value >= self.value)

    def describe(self) -> str:
        return f"{self.name} {'<=' if self.upper else '>='} {self.value:g}"


def parse_constraint(text: str, upper: bool) -> Constraint:
    """`NAME=VALUE` of --max (upper) or --min as a Constraint; ConfigError in one line when it is not one."""
    import math

    option = "--max" if upper else "--min"
    name, eq, value = text.partition("=")
    name = name.strip()
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not eq or not math.isfinite(number):
        raise ConfigError(f"{option} {text}: expected NAME=VALUE with a finite number, e.g. {option} false_people_s=1")
    return Constraint(check_name(name, option), number, upper)
