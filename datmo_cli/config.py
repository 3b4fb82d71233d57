"""Config files: TOML with one table per stage (`[features]`, `[track]`), shared by the commands."""

from __future__ import annotations

import tomllib
from pathlib import Path

from .errors import ConfigError

STAGES = ("features", "track")   # the tables of a config file, one per stage


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
