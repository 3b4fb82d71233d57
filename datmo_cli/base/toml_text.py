"""TOML text from a user's file (a `--config` file, a `--scene` file) read into a dict, with every way it can
fail as a ConfigError naming the file: invalid TOML; a UTF-8 BOM at its start (some editors write one) is
read as nothing, not refused as "Invalid statement"; a whole number of more digits than Python converts
(sys.get_int_max_str_digits, 4,300 by default) and arrays or tables nested too deeply to parse are refused
in one line, not exit 70."""

from __future__ import annotations

import sys
import tomllib
from typing import Any

from .errors import ConfigError


def loads(text: str, source: object, invalid: str = "") -> dict[str, Any]:
    """The TOML document `text` of the file `source` (named in errors); `invalid` goes before a TOML syntax
    error's text (e.g. "invalid TOML: ")."""
    try:
        return tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: {invalid}{exc}") from None
    except ValueError:  # Python's limit on the digits of a whole number read from text
        raise ConfigError(
            f"{source}: a whole number of more than {sys.get_int_max_str_digits():,} digits (no parameter takes one)"
        ) from None
    except RecursionError:
        raise ConfigError(f"{source}: arrays or tables nested too deeply to read (no parameter nests)") from None
