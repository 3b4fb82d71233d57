"""The configuration tree: `DatmoConfig`, one section per stage (`[features]`, `[track]` in a TOML file), its
one loader (`load`: defaults, then the file, then the options) and the file conventions the commands share.

Each section's fields carry their own default, range and help (bounds.param); `bounds.validate` is the one
check of a section, `commands.options.param_option` builds the Click options from the same fields.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .bounds import Bound, Section, bounds_of, validate
from .errors import ConfigError
from .perception.params import FeatureParams
from .tracking.params import TrackingParams

SECTIONS: dict[str, type[Section]] = {"features": FeatureParams, "track": TrackingParams}
STAGES = tuple(SECTIONS)   # the tables of a config file, one per stage
BOUNDS: dict[str, dict[str, Bound]] = {s: bounds_of(c) for s, c in SECTIONS.items()}   # section -> key -> Bound


@dataclass(frozen=True)
class DatmoConfig:
    """Every parameter of datmo: the `[features]` section (segmentation, features, landmarks, legs) and the
    `[track]` section (tracking and classification)."""

    features: FeatureParams = field(default_factory=FeatureParams)
    track: TrackingParams = field(default_factory=TrackingParams)

    def to_dict(self) -> dict[str, dict]:
        """Section -> key -> value, as the TOML file and the provenance hold them."""
        return {s: getattr(self, s).to_dict() for s in STAGES}

    def replace(self, **sections: dict) -> DatmoConfig:
        """A copy with each given section's values changed (section -> key -> value; None values ignored)."""
        return DatmoConfig(**{s: getattr(self, s).replace(**sections.get(s, {})) for s in STAGES})




def load(path: str | Path | None = None, options: dict[str, dict] | None = None) -> DatmoConfig:
    """The configuration: the defaults, overridden by the `[features]` and `[track]` tables of the TOML file
    at `path` (None: no file), overridden by `options` (section -> key -> value; None values ignored).
    ConfigError names the file, the key, the value and what is allowed."""
    tables = {s: {} for s in STAGES}
    if path is not None:
        tables = {s: read_table(path, s) for s in STAGES}
    sections = {}
    for s, cls in SECTIONS.items():
        given = validate(cls, tables[s], f"{path}: {s}" if path is not None else s)
        sections[s] = given.replace(**(options or {}).get(s, {}))
    return DatmoConfig(**sections)


def read_table(path: str | Path, name: str) -> dict:
    """The `[name]` table of a TOML file, or its top-level keys when it has no such table (other stages'
    tables are then left out). ConfigError names the file and what is wrong."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    for stage in STAGES:
        if stage in data and not isinstance(data[stage], dict):
            raise ConfigError(f"{path}: {stage} must be a table ([{stage}] with its parameters), "
                              f"got {data[stage]!r}")
    table = data.get(name, data)
    if table is data:
        table = {k: v for k, v in data.items() if not isinstance(v, dict) and k not in STAGES}
    return table


LOCAL = "datmo.toml"   # picked up from the current folder when no --config is given
PICKED_KEY = "datmo.config_picked"   # in the Click context's meta: ./datmo.toml was picked up


def effective_path(config: str | Path | None, no_config: bool) -> Path | None:
    """The config file a command uses: `--config`, else ./datmo.toml when present (said on stderr unless
    --quiet, and noted for the provenance), else none; `--no-config` ignores both."""
    if no_config and config is not None:
        raise ConfigError("--config and --no-config: give one or the other")
    if no_config:
        return None
    if config is not None:
        return Path(config)
    local = Path(LOCAL)
    if not local.is_file():
        return None
    import click

    from .progress import say

    ctx = click.get_current_context(silent=True)
    if ctx is not None:
        ctx.meta[PICKED_KEY] = True
    say(f"datmo: using ./{LOCAL}")
    return local


def provenance_line(line: str) -> str:
    """The command line recorded in an output's provenance: `line`, with `--config datmo.toml` appended when
    ./datmo.toml was picked up without being named (so the record says which file set the parameters)."""
    import click

    ctx = click.get_current_context(silent=True)
    return f"{line} --config {LOCAL}" if ctx is not None and ctx.meta.get(PICKED_KEY) else line


def _toml_value(value: object) -> str:
    """`value` as a TOML value that reads back equal (floats by repr, strings JSON-escaped)."""
    import json

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    raise ConfigError(f"cannot write {value!r} as TOML")


def to_toml(tables: dict[str, dict], sources: dict[str, dict[str, str]], header: str = "") -> str:
    """TOML text of `tables` (stage -> key -> value), each key followed by a comment naming where its value
    came from (sources: stage -> key -> source)."""
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    for stage, table in tables.items():
        if lines:
            lines.append("")
        lines.append(f"[{stage}]")
        width = max((len(f"{k} = {_toml_value(v)}") for k, v in table.items()), default=0)
        for key, value in table.items():
            entry = f"{key} = {_toml_value(value)}"
            lines.append(f"{entry:{width}s}  # {sources[stage][key]}")
    return "\n".join(lines) + "\n"
