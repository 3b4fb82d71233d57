"""Provenance: what made a log (the command, its parameters, its inputs' SHA-256), as MCAP metadata records."""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from .. import __version__


def sha256_of(path: str | Path) -> str:
    """SHA-256 of a file, or of a directory's files (sorted by relative path) for ROS 2 bag folders."""
    path = Path(path)
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for p in files:
        if path.is_dir():
            h.update(str(p.relative_to(path)).encode())
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


@dataclass
class Provenance:
    """What made a file: the command, its effective parameters and its inputs (hashed on write).
    `command_line`: the command line as the caller was started with it (default `datmo COMMAND`)."""

    command: str
    params: dict = field(default_factory=dict)
    inputs: list = field(default_factory=list)
    command_line: str | None = None
    names: list | None = None  # what the inputs are called in the records (e.g. the URL a local copy came from)

    def records(self) -> dict[str, dict[str, str]]:
        line = self.command_line if self.command_line is not None else f"datmo {self.command}"
        return {
            "datmo": {"tool": "datmo", "version": __version__, "command": self.command, "command_line": _text(line)},
            "datmo.params": {str(k): json.dumps(v, sort_keys=True, default=str) for k, v in self.params.items()},
            "datmo.inputs": {
                _text(str(name)): sha256_of(p) for name, p in zip(self.names or self.inputs, self.inputs, strict=True)
            },
        }


def _text(name: str) -> str:
    """`name` as valid UTF-8 text: the bytes of a file name that is not UTF-8 (os.fsdecode gives them as
    surrogates, which MCAP cannot store) as \\xNN escapes."""
    return os.fsencode(name).decode("utf-8", "backslashreplace")
