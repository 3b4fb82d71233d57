"""A batch's inputs: the logs that INPUTS name (files, folders searched recursively, globs; local paths or fsspec
URLs), each with its output path under OUT_DIR."""

from __future__ import annotations

import glob
import os
from pathlib import Path

from ..base.errors import InputError
from .locations import fs_of, inside, join, local, remote

LOG_SUFFIXES = (".mcap",)


def _is_log(name: str) -> bool:
    base = os.path.basename(name)
    return base.lower().endswith(LOG_SUFFIXES) and not base.startswith(".")


def discover(specs: list[str], out_dir: str, bag_dir: bool = False) -> list[tuple[str, str]]:
    """(input, output) for every log that `specs` name, in order, without repeats.

    A file is taken as it is (its output is OUT_DIR/STEM.mcap); a folder is searched recursively for .mcap
    logs (hidden files and the output folder itself left out) and its logs keep their relative paths under
    OUT_DIR; a glob (`*`, `?`, `[`, `**`) takes the logs it matches. A glob or folder without logs, or two
    inputs with the same output, is an InputError naming them. With `bag_dir` each output is the log file of a
    ROS 2 bag folder, OUT_DIR/STEM/STEM_0.mcap (log.bagdir.member_path).
    """
    out_root = None if remote(out_dir) else os.path.abspath(local(out_dir))
    pairs: list[tuple[str, str]] = []
    for spec in specs:
        for src, rel in _expand(spec, out_root):
            name = str(Path(rel).with_suffix(".mcap"))
            if bag_dir:
                from ..logs.bagdir import member_path

                name = member_path(name)
            pairs.append((src, join(out_dir, name)))
    seen_in: set[str] = set()
    seen_out: dict[str, str] = {}
    out: list[tuple[str, str]] = []
    for src, dst in pairs:
        if src in seen_in:
            continue
        seen_in.add(src)
        if dst in seen_out:
            raise InputError(f"{src}: same output name as {seen_out[dst]} ({dst}); rename one of them")
        seen_out[dst] = src
        out.append((src, dst))
    return out


def _expand(spec: str, out_root: str | None) -> list[tuple[str, str]]:
    """(input, output path relative to OUT_DIR) for one INPUTS item."""
    magic = glob.has_magic(spec.split("://", 1)[-1])
    if remote(spec):
        fs, path = fs_of(spec)
        if magic and not fs.exists(path):  # a name holding [, * or ? that exists is that file, not a pattern
            found = [p for p in sorted(fs.glob(path)) if _is_log(p) and fs.isfile(p)]
            if not found:
                raise InputError(f"{spec}: no .mcap log matches")
            return [(fs.unstrip_protocol(p), os.path.basename(p)) for p in found]
        if fs.isdir(path):
            found = [p for p in sorted(fs.find(path)) if _is_log(p)]
            if not found:
                raise InputError(f"{spec}: no .mcap logs in this folder")
            return [(fs.unstrip_protocol(p), os.path.relpath(p, path)) for p in found]
        return [(spec, os.path.basename(path))]
    path = local(spec)
    magic = magic and not os.path.lexists(path)  # a name holding [, * or ? that exists is that file or folder
    bag = bag_of(path)
    if bag is not None and not magic:
        return [(bag, os.path.basename(bag))]
    if magic:
        found = [os.path.abspath(p) for p in sorted(glob.glob(path, recursive=True)) if os.path.isfile(p)]
        found = [p for p in found if _is_log(p) and not inside(p, out_root)]
        if not found:
            raise InputError(f"{spec}: no .mcap log matches")
        return [(p, os.path.basename(p)) for p in found]
    if os.path.isdir(path):
        root = os.path.abspath(path)
        found = []
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not inside(os.path.join(folder, d), out_root))
            found += [os.path.join(folder, f) for f in sorted(files) if _is_log(f)]
        if not found:
            raise InputError(f"{spec}: no .mcap logs in this folder")
        return [(p, os.path.relpath(p, root)) for p in found]
    return [(os.path.abspath(path), os.path.basename(path))]  # a missing file fails as its own input


def bag_of(path: str) -> str | None:
    """The absolute path of the ROS 2 bag folder that local `path` names (the folder, or its .db3 file), else
    None. A bag is one input, converted by its task (run_task), and its output is named after the folder."""
    folder = os.path.dirname(path) if path.endswith(".db3") else path
    if os.path.isdir(folder) and os.path.isfile(os.path.join(folder, "metadata.yaml")):
        return os.path.abspath(folder)
    return None
