"""The configuration tree: `DatmoConfig`, one section per stage (`[features]`, `[track]` in a TOML file), its
one loader (`load`: defaults, then the file, then the options) and the file conventions the commands share.

Each section's fields carry their own default, range and help (bounds.param); `bounds.validate` is the one
check of a section, `commands.options.param_option` builds the Click options from the same fields.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from ..base.bounds import Bound, Section, bounds_of, validate
from ..base.errors import ConfigError
from ..perception.params import FeatureParams
from ..tracking.params import TrackingParams

SECTIONS: dict[str, type[Section]] = {"features": FeatureParams, "track": TrackingParams}
STAGES = tuple(SECTIONS)  # the tables of a config file, one per stage
BOUNDS: dict[str, dict[str, Bound]] = {s: bounds_of(c) for s, c in SECTIONS.items()}  # section -> key -> Bound


@dataclass(frozen=True)
class DatmoConfig:
    """Every parameter of datmo: the `[features]` section (segmentation, features, landmarks, legs) and the
    `[track]` section (tracking and classification)."""

    features: FeatureParams = field(default_factory=FeatureParams)
    track: TrackingParams = field(default_factory=TrackingParams)

    def __post_init__(self) -> None:
        for s in STAGES:  # a parameter with its home in another section takes its value from there
            section = getattr(self, s)
            home = {name: self.get(key) for name, key in same_as(type(section)).items()}
            if any(getattr(section, name) != value for name, value in home.items()):
                object.__setattr__(self, s, section.replace(**home))

    def get(self, key: str) -> object:
        """The value of 'section.name'."""
        section, _, name = key.partition(".")
        return getattr(getattr(self, section), name)

    def to_dict(self) -> dict[str, dict]:
        """Section -> key -> value, as a TOML file holds them (each parameter once, in its home section)."""
        return {
            s: {k: v for k, v in getattr(self, s).to_dict().items() if k not in same_as(SECTIONS[s])} for s in STAGES
        }

    def replace(self, **sections: dict) -> DatmoConfig:
        """A copy with each given section's values changed (section -> key -> value; None values ignored)."""
        return _build({s: getattr(self, s) for s in STAGES}, sections)


def same_as(section: type[Section]) -> dict[str, str]:
    """The fields of `section` that are a parameter whose home is another section: name -> 'section.key'."""
    return {f.name: f.metadata["same_as"] for f in fields(section) if f.metadata.get("same_as")}


def _build(sections: dict[str, Section], changes: dict[str, dict], where: str = "") -> DatmoConfig:
    """DatmoConfig of `sections` with `changes` (section -> key -> value; None values ignored); a parameter
    given in a section that is not its home is set at its home, and given in both with two values is refused."""
    moved = {s: dict(changes.get(s, {})) for s in STAGES}
    for s in STAGES:
        for name, key in same_as(SECTIONS[s]).items():
            if moved[s].get(name) is None:
                moved[s].pop(name, None)
                continue
            value, (home, _, home_key) = moved[s].pop(name), key.partition(".")
            if moved[home].get(home_key) not in (None, value):
                raise ConfigError(
                    f"{where}{s}.{name} and {key} are one parameter (its home is {key}), given "
                    f"as {value!r} and {moved[home][home_key]!r}; give it once, as {key}"
                )
            moved[home][home_key] = value
    built: dict[str, Any] = {s: sections[s].replace(**moved[s]) for s in STAGES}
    return DatmoConfig(**built)


def load(path: str | Path | None = None, options: dict[str, dict] | None = None) -> DatmoConfig:
    """The configuration: the defaults, overridden by the `[features]` and `[track]` tables of the TOML file
    at `path` (None: no file), overridden by `options` (section -> key -> value; None values ignored).
    ConfigError names the file, the key, the value and what is allowed. A key written in a section that is
    not its home (track.d_max: features.d_max) is read as the same parameter."""
    tables = read_tables(path) if path is not None else {s: {} for s in STAGES}
    where = f"{path}: " if path is not None else ""
    given = {s: validate(cls, tables[s], f"{where}{s}") for s, cls in SECTIONS.items()}  # each where written
    cfg = _build(
        {s: cls() for s, cls in SECTIONS.items()},
        {s: {k: getattr(given[s], k) for k in tables[s]} for s in STAGES},
        where,
    )
    return cfg.replace(**(options or {}))


def read_tables(path: str | Path) -> dict[str, dict]:
    """The `[features]` and `[track]` tables of a TOML file, by section (an absent table: {}). Keys at the top
    level, outside any table, go to the section that declares them (features first: the home of d_max); one
    neither declares is an unknown parameter, and any other table (a misspelt `[tracks]` or `[Features]`) is
    refused, not ignored. ConfigError names the file and what is wrong."""
    from ..base import input_files, toml_text

    path = Path(path)
    try:
        text = input_files.read_text(path, input_files.MAX_CONFIG_BYTES, "configuration file")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    data = toml_text.loads(text, path)
    for stage in STAGES:
        if stage in data and not isinstance(data[stage], dict):
            raise ConfigError(f"{path}: {stage} must be a table ([{stage}] with its parameters), got {data[stage]!r}")
    tables = {s: dict(data.get(s, {})) for s in STAGES}
    for key, value in data.items():
        if key in STAGES:
            continue
        if isinstance(value, dict):
            raise ConfigError(
                f"{path}: [{key}]: unknown table{_did_you_mean(key)} (datmo reads "
                f"{' and '.join(f'[{s}]' for s in STAGES)})"
            )
        owner = next((s for s in STAGES if s not in data and key in _names(SECTIONS[s])), None)
        if owner is None:
            raise ConfigError(
                f"{path}: {key}: unknown parameter at the top level (not in a [features] or [track] "
                "table, nor a key of a section without its table)"
            )
        tables[owner][key] = value
    return tables


def _did_you_mean(table: str) -> str:
    """'; did you mean [track]?' for a table name near a stage's (by case or spelling), else ''."""
    import difflib

    near = [s for s in STAGES if s == table.lower().strip()] or difflib.get_close_matches(table.lower(), STAGES, 1)
    return f"; did you mean [{near[0]}]?" if near else ""


def _names(section: type[Section]) -> set[str]:
    return {f.name for f in fields(section)}


LOCAL = "datmo.toml"  # picked up from the current folder when no --config is given
PICKED_KEY = "datmo.config_picked"  # in the running command's meta (progress.command_meta): ./datmo.toml was picked up


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
    from ..base.progress import command_meta, say

    meta = command_meta()
    if meta is not None:
        meta[PICKED_KEY] = True
    say(f"datmo: using ./{LOCAL}")
    return local


def provenance_line(line: str) -> str:
    """The command line recorded in an output's provenance: `line`, with `--config datmo.toml` appended when
    ./datmo.toml was picked up without being named (so the record says which file set the parameters)."""
    from ..base.progress import command_meta

    meta = command_meta()
    return f"{line} --config {LOCAL}" if meta is not None and meta.get(PICKED_KEY) else line


def _toml_value(value: object) -> str:
    """`value` as a TOML value that reads back equal (floats by repr, strings JSON-escaped, and every
    character text.printable escapes written as TOML's \\uXXXX: nothing raw reaches a terminal)."""
    import json

    from ..base.text import UNSAFE

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return UNSAFE.sub(_toml_escape, json.dumps(value, ensure_ascii=False))
    raise ConfigError(f"cannot write {value!r} as TOML")


def _toml_escape(match) -> str:
    c = ord(match.group())
    return f"\\u{c:04x}" if c < 0x10000 else f"\\U{c:08x}"


def to_toml(tables: dict[str, dict], sources: dict[str, dict[str, str]], header: str = "") -> str:
    """TOML text of `tables` (stage -> key -> value), each key followed by a comment naming where its value
    came from (sources: stage -> key -> source)."""
    from ..base.text import printable

    lines = [f"# {printable(h)}" for h in header.splitlines()] if header else []
    for stage, table in tables.items():
        if lines:
            lines.append("")
        lines.append(f"[{stage}]")
        width = max((len(f"{k} = {_toml_value(v)}") for k, v in table.items()), default=0)
        for key, value in table.items():
            entry = f"{key} = {_toml_value(value)}"
            lines.append(f"{entry:{width}s}  # {printable(sources[stage][key])}")
    return "\n".join(lines) + "\n"
