"""ROS 2 bag folders: a datmo log laid out as rosbag2 lays out a bag, so `ros2 bag play OUT` and the tools that
open bag folders (rosbags, ros2 bag info) take it.

A bag folder NAME holds NAME_0.mcap (the log, as datmo writes every log) and metadata.yaml (rosbag2's
`rosbag2_bagfile_information`: storage, time span, message count, each topic's type, serialization format,
offered QoS and message count, and the same figures per file). `writing(NAME)` makes it atomically: the log is
written into a temporary folder beside NAME, metadata.yaml made from the finished file's summary, and the
temporary folder renamed to NAME; on any error or signal it is removed and NAME is left as it was.

What may be replaced, as outputs.check_output decides for files: a missing name or an empty folder always; a
bag folder (metadata.yaml and only the files it lists) with --force; anything else (a file, a symlink, a folder
holding anything else) never, nor a folder holding an input.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path, PurePath

from ..base import outputs
from ..base.errors import OutputError, OutputExistsError
from .mcap_reader import LogContents, summary

METADATA = "metadata.yaml"
# rosbag2's metadata version of ROS 2 Humble: Humble and every later release read it, and so does rosbags.
# Later versions add fields Humble does not need (9 also writes QoS as lists, which Humble cannot parse).
VERSION = 5
STORAGE = "mcap"


def member(folder: str | Path) -> Path:
    """The log file inside bag folder `folder`: FOLDER/NAME_0.mcap, the first (and only) file as rosbag2 names it."""
    folder = Path(folder)
    return folder / f"{folder.name}_0.mcap"


def member_path(output: str) -> str:
    """`datmo run`'s output name for a bag: OUT/REL.mcap -> OUT/REL/REL_0.mcap (its folder is the bag)."""
    stem = os.path.splitext(output)[0]
    return os.path.join(stem, f"{os.path.basename(stem)}_0.mcap")


# ----------------------------------------------------------------------------------------------- checks


def _not_bag(folder: Path, entries: list[str]) -> str | None:
    """Why `folder` (holding `entries`) is not a bag, naming what is foreign in it, or None when it is one:
    metadata.yaml and only the regular files it lists."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    if METADATA not in entries:
        return f"it holds {entries[0]!r} and no {METADATA}"
    try:
        info = YAML(typ="safe").load((folder / METADATA).read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        listed = {PurePath(str(x)).name for x in info["relative_file_paths"]}
    except (OSError, YAMLError, UnicodeDecodeError, KeyError, TypeError):
        return f"its {METADATA} is not a ROS 2 bag's"
    for name in entries:
        if name != METADATA and name not in listed:
            return f"it holds {name!r}, which its {METADATA} does not list"
        if name != METADATA and not stat.S_ISREG(os.lstat(folder / name).st_mode):
            return f"it holds {name!r}, which is not a regular file"
    return None


def _state(folder: Path, force: bool) -> str:
    """ "missing", "empty" or "bag" (which `force` allows replacing); else OutputError saying why not."""
    try:
        st = os.lstat(folder)
    except FileNotFoundError:
        return "missing"
    except OSError as exc:
        raise outputs.os_error(exc, folder) from None
    if stat.S_ISLNK(st.st_mode):
        raise OutputError(f"{folder}: is a symbolic link; a bag folder never replaces it (even with --force)")
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{folder}: exists and is not a folder; a bag folder never replaces it (even with --force)")
    try:
        entries = sorted(os.listdir(folder))
    except OSError as exc:
        raise outputs.os_error(exc, folder) from None
    if not entries:
        return "empty"
    foreign = _not_bag(folder, entries)
    if foreign:
        raise OutputError(
            f"{folder}: a folder that is not a ROS 2 bag ({foreign}); it is never replaced (even with --force)"
        )
    if not force:
        raise OutputExistsError(f"{folder}: exists; use --force to replace it")
    return "bag"


def _inside(path: str | Path, folder: Path) -> bool:
    real, top = os.path.realpath(path), os.path.realpath(folder)
    return real == top or real.startswith(top.rstrip(os.sep) + os.sep)


def check_output(folder: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = ()) -> Path:
    """`folder` as a Path when a bag folder may be written there (see the module docstring); else OutputError
    (or OutputExistsError) naming it. A trailing '/' is taken as it is meant: the folder."""
    raw = os.fspath(folder)
    p = Path(raw.rstrip(os.sep) or raw)
    if p.name in ("", ".", ".."):
        raise OutputError(f"{raw}: give the bag folder a name")
    if p.suffix.lower() == ".mcap":
        raise OutputError(
            f"{raw}: with --bag-dir the output is a folder (holding {member(p.with_suffix('')).name} "
            f"and {METADATA}); name it without .mcap, e.g. {p.with_suffix('')}"
        )
    parent = outputs.folder_of(p)
    size = len(os.fsencode(member(p).name))
    limit = outputs.name_max(parent if parent.is_dir() else Path("."))
    if size > limit:
        raise OutputError(
            f"{raw}: name too long for a bag folder (its file {member(p).name} takes {size} bytes; at most {limit})"
        )
    _state(p, force)
    for inp in inputs:
        if os.path.lexists(inp) and _inside(inp, p):
            raise OutputError(f"{p}: the bag folder would replace the input {inp}")
    outputs.check_folder(parent)
    return p


# ---------------------------------------------------------------------------------------------- writing


def _scalar(text: str) -> str:
    """A YAML double-quoted scalar (JSON's escapes are YAML's)."""
    return json.dumps(text)


def metadata_text(log: LogContents, file_name: str) -> str:
    """metadata.yaml of a bag whose one file `file_name` holds `log` (read with summary): rosbag2's
    fields of VERSION, each channel as a topic with its offered QoS as the channel's metadata gives it (the
    same text, so readers that match the file's channels with the metadata find them equal)."""
    channels = sorted(log.channels.values(), key=lambda c: c.id)
    count = sum(c.count for c in channels)
    start = log.start_ns if count else 0
    duration = log.end_ns - start if count else 0
    lines = [
        "rosbag2_bagfile_information:",
        f"  version: {VERSION}",
        f"  storage_identifier: {STORAGE}",
        "  duration:",
        f"    nanoseconds: {duration}",
        "  starting_time:",
        f"    nanoseconds_since_epoch: {start}",
        f"  message_count: {count}",
        "  topics_with_message_count:" + ("" if channels else " []"),
    ]
    for c in channels:
        lines += [
            "    - topic_metadata:",
            f"        name: {_scalar(c.topic)}",
            f"        type: {_scalar(c.msgtype)}",
            f"        serialization_format: {_scalar(c.message_encoding)}",
            f"        offered_qos_profiles: {_scalar(c.metadata.get('offered_qos_profiles', ''))}",
            f"      message_count: {c.count}",
        ]
    lines += [
        '  compression_format: ""',
        '  compression_mode: ""',
        "  relative_file_paths:",
        f"    - {_scalar(file_name)}",
        "  files:",
        f"    - path: {_scalar(file_name)}",
        "      starting_time:",
        f"        nanoseconds_since_epoch: {start}",
        "      duration:",
        f"        nanoseconds: {duration}",
        f"      message_count: {count}",
    ]
    return "\n".join(lines) + "\n"


def _write_metadata(tmp: Path, log_file: Path, dest: Path) -> None:
    with outputs.writing(dest):
        text = metadata_text(summary(log_file), log_file.name)
        with open(tmp / METADATA, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())


def _remove(tmp: Path) -> None:
    with outputs.critical():
        shutil.rmtree(tmp, ignore_errors=True)


def _commit(tmp: Path, dest: Path, force: bool) -> None:
    """Rename the complete `tmp` to `dest` (checked again: something may have appeared there meanwhile); an old
    bag there is moved aside first and removed once the new one is in place."""
    with outputs.critical():
        state = _state(dest, force)
        aside = outputs.temp_path(dest) if state == "bag" else None
        try:
            if aside is not None:
                outputs.note("+", aside)
                os.rename(dest, aside)
            try:
                os.replace(tmp, dest)  # a missing name or an empty folder
            except OSError:
                if aside is not None:
                    os.rename(aside, dest)
                raise
        except OSError as exc:
            raise outputs.os_error(exc, dest, "renaming the finished bag folder into place") from None
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def writing(folder: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Write a bag folder at `folder` (checked by check_output): the block writes the log to the path it is
    given (a LogWriter with force=False: the file is new); then metadata.yaml is made and the folder renamed
    into place. On any error or signal the temporary folder is removed and `folder` left as it was."""
    dest = check_output(folder, force=force, inputs=inputs)
    with outputs.critical():
        tmp = outputs.temp_path(dest)
        try:
            os.mkdir(tmp)
        except OSError as exc:
            raise outputs.os_error(exc, outputs.folder_of(dest), "creating a folder there") from None
        outputs.note("+", tmp)  # a batch's journal: removed by the batch if this process dies with it there
    try:
        log_file = tmp / member(dest).name
        yield log_file
        _write_metadata(tmp, log_file, dest)
        _commit(tmp, dest, force)
    except OutputError as exc:  # a write error names the bag folder, not the temporary one
        _remove(tmp)
        text = str(exc).replace(os.fspath(log_file), os.fspath(dest)).replace(os.fspath(tmp), os.fspath(dest))
        raise type(exc)(text) from exc
    except BaseException:
        _remove(tmp)
        raise


@contextmanager
def output(path: str | Path, bag: bool, *, force: bool = False, inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Where a command writes its log: `path` itself, or with `bag` the log file of a bag folder at `path`
    (written as `writing` does)."""
    if not bag:
        yield Path(path)
        return
    with writing(path, force=force, inputs=inputs) as log_file:
        yield log_file


def plot_path(output: str | Path) -> Path:
    """Where `datmo run --plot` draws the bag whose log file is `output`: beside the bag folder, OUT/NAME.png."""
    return Path(output).parent.with_suffix(".png")
