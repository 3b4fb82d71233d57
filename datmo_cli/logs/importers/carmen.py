"""CARMEN text logs (and g2o files with ROBOTLASER1 lines) into a ScanRun and Odometry: the laser stream chosen,
its geometry, no-return limit, stamps and poses settled (carmen_conventions.py) from a parsed log
(carmen_parse.py, which lists the messages read), and the import streamed block by block.

Streaming (`stream_carmen`): the conventions need the whole log (its largest reading, its stamps, which laser
messages it holds), so one pass parses every line and spools the parsed scans to a temporary file, keeping
counts and a few numbers (StampCheck); the scans are then read back and written a block at a time, the
ODOM poses merged in time order. Memory does not grow with the log; the spool takes 8 bytes a reading.
"""

from __future__ import annotations

import gzip
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...base.errors import DatmoError, GeometryError, InputError
from ..scan import Odometry, ScanGeometry, ScanRun
from .carmen_conventions import flaser_angles, no_return_limit_of
from .carmen_parse import LASER_MESSAGES, CarmenParse, LaserStream, parse_lines


def pick_stream(parse: CarmenParse, topic: str | None, label: str) -> LaserStream:
    """The laser stream to import: `topic`, or the only one. Raises InputError naming the choices."""
    names = [n for n in LASER_MESSAGES if n in parse.streams and parse.streams[n].count]
    listing = ", ".join(f"{n} ({parse.counts.get(n, 0)} scans)" for n in names)
    if topic is not None:
        if topic not in names:
            have = f"it has {listing}" if names else "it has no laser scans"
            raise InputError(f"{label}: no {topic} scans; {have}")
        return parse.streams[topic]
    if not names:
        skipped = f"; skipped {parse.malformed} malformed lines" if parse.malformed else ""
        raise InputError(
            f"{label}: no laser scans (no valid FLASER, RLASER, RAWLASER1-4 or ROBOTLASER1-2 lines{skipped})"
        )
    if len(names) > 1:
        raise InputError(f"{label}: several laser streams, choose one with --topic: {listing}")
    return parse.streams[names[0]]


@dataclass
class _Plan:
    """How a parsed log's stream becomes scans and poses (what `build` settles from the whole log)."""

    stream: LaserStream
    geometry: ScanGeometry
    limit: float
    flip: bool
    stamps_note: str | None
    odometry_source: str | None  # the laser message (its poses), "ODOM", or None
    warnings: list[str]
    facts: dict
    pose_frame: str = "odom"  # the poses' frame: "map" for SLAM-corrected poses (see pose_frame)


def pose_frame(label: str) -> str:
    """The frame of a log's poses: "map" when its file name says they are SLAM-corrected (Radish's
    `*-corrected` logs, whose FLASER x y theta, and odom_x odom_y odom_theta alike, come out of SLAM), else
    "odom" (raw odometry). The content cannot tell: a corrected log's two poses are the same numbers."""
    return "map" if "corrected" in Path(label).name.lower() else "odom"


def plan(parse: CarmenParse, topic: str | None = None, label: str = "<text>") -> _Plan:
    """Settle geometry, no-return limit, stamps and odometry of a parsed log (pure). Its facts'
    "no_return_readings" is counted as `blocks` gives the scans."""
    s = pick_stream(parse, topic, label)
    warnings: list[str] = []
    n = s.n_beams
    flip = False
    if s.geometry is None:
        angle_min, inc = flaser_angles(n)
        limit = no_return_limit_of(s.top, None)
        if n not in (180, 181, 360, 361):
            warnings.append(f"{label}: {s.name} has {n} beams; assumed they span -90°..+90° inclusive")
        flip = parse.params.get("laser_front_laser_flipped", "off").lower() in ("1", "on", "yes", "true")
    else:
        angle_min, inc, stated = s.geometry
        limit = no_return_limit_of(s.top, stated)
    fixed = s.stamps.note(s.all_stamps)
    synthesised = fixed is not None and fixed.endswith("per scan")
    if fixed:
        warnings.append(f"{label}: {s.name} timestamps: {fixed}")
    frame = "rear_laser" if s.name == "RLASER" else "laser"
    geometry = ScanGeometry(
        angle_min=float(angle_min),
        angle_increment=float(inc),
        n_beams=n,
        range_min=0.0,
        range_max=float(limit),
        frame_id=frame,
    )
    odom = parse.odom
    if s.posed == s.count:  # the laser lines carry the poses
        odom_source = s.name if s.unposed.count < s.count else None
        if s.unposed.count:
            warnings.append(s.unposed.said(label, s.name, s.count))
    elif not len(odom):
        odom_source = None
    elif odom.unposed.count == odom.count:
        warnings.append(odom.unposed.said(label, "ODOM", odom.count))
        odom_source = None
    elif synthesised or odom.stamps.mode != "keep":
        warnings.append(f"{label}: ODOM poses not written: their stamps cannot be matched to the scans")
        odom_source = None
    else:
        odom_source = "ODOM"
        if odom.unposed.count:
            warnings.append(odom.unposed.said(label, "ODOM", odom.count))
    if parse.malformed:
        where = ", ".join(str(i) for i in parse.malformed_lines)
        warnings.insert(
            0,
            f"{label}: skipped {parse.malformed} malformed line{'s' if parse.malformed != 1 else ''}"
            f" (first at line {where})",
        )
    facts = {
        "message": s.name,
        "scans": s.count,
        "beams": n,
        "no_return_at_m": float(limit),
        "no_return_readings": 0,
        "stamps": fixed or "ipc_timestamp",
        "malformed_lines": parse.malformed,
        "odometry_source": odom_source,
    }
    frame = pose_frame(label)
    if odom_source is not None:
        facts["pose_frame"] = frame
    return _Plan(s, geometry, limit, flip, fixed, odom_source, warnings, facts, frame)


def blocks(parse: CarmenParse, p: _Plan, size: int) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
    """The planned stream's scans and poses, `size` scans at a time, in time order (scans before poses of
    the same stamp): (scans, their laser poses) or, for ODOM poses, (scans, None) and (None, poses) pieces."""
    s = p.stream
    s.stamps.rewind()

    def scans() -> Iterator[tuple[ScanRun, Odometry | None]]:
        for ranges, rem, ipc, poses in s.blocks(size):
            if p.flip:
                ranges = ranges[:, ::-1]
            no_return = ranges >= p.limit
            ranges[no_return] = np.inf
            p.facts["no_return_readings"] += int(no_return.sum())
            stamps = s.stamps.apply(ipc)
            no_rem = np.zeros((len(stamps), 0), np.float32)  # what ScanRun makes of None
            run = ScanRun(stamps, ranges.astype(np.float32), p.geometry, rem if rem is not None else no_rem)
            odom = None
            if p.odometry_source == s.name:
                ok = np.isfinite(poses).all(axis=1)  # a pose that is not a number is left out (plan warns)
                odom = Odometry(
                    stamps[ok],
                    poses[ok, 0],
                    poses[ok, 1],
                    poses[ok, 2],
                    frame_id=p.pose_frame,
                    child_frame_id=p.geometry.frame_id,
                )
            yield run, odom

    if p.odometry_source != "ODOM":
        yield from scans()
        return
    check = parse.odom.stamps
    check.rewind()

    def poses() -> Iterator[Odometry]:
        for rows in parse.odom.blocks(size):
            stamps = check.apply(rows[:, 0])  # every row's, in order (a repair carries on from the one before)
            ok = np.isfinite(rows[:, 1:]).all(axis=1)
            yield Odometry(stamps[ok], rows[ok, 1], rows[ok, 2], rows[ok, 3], frame_id=p.pose_frame)

    yield from merge((run for run, _ in scans()), poses())


def merge(runs: Iterable[ScanRun], odoms: Iterable[Odometry]) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
    """Blocks of scans and of poses, each in time order, paired: each block of scans with the poses stamped
    up to its last scan, so every message of a pair comes before every message of the next (the writer
    orders a pair's messages)."""
    odoms = iter(odoms)
    pending: list[Odometry] = []
    more = True
    for run in runs:
        last = int(run.stamps[-1])
        while more and (not pending or int(pending[-1].stamps[-1]) <= last):
            nxt = next(odoms, None)
            if nxt is None:
                more = False
            elif len(nxt):
                pending.append(nxt)
        if not pending:
            yield run, None
            continue
        o = _cat(pending)
        m = int(np.searchsorted(o.stamps, last, side="right"))
        pending = [_cut(o, m, len(o))] if m < len(o) else []
        yield run, (_cut(o, 0, m) if m else None)
    for o in pending:
        yield None, o
    for o in odoms:
        if len(o):
            yield None, o


def _cut(o: Odometry, a: int, b: int) -> Odometry:
    return Odometry(o.stamps[a:b], o.x[a:b], o.y[a:b], o.theta[a:b], o.frame_id, o.child_frame_id)


def _cat(parts: list[Odometry]) -> Odometry:
    if len(parts) == 1:
        return parts[0]
    o = parts[0]
    stamps, x, y, theta = (np.concatenate([getattr(q, f) for q in parts]) for f in ("stamps", "x", "y", "theta"))
    return Odometry(stamps, x, y, theta, o.frame_id, o.child_frame_id)


def build(parse: CarmenParse, topic: str | None = None, label: str = "<text>"):
    """(ScanRun, Odometry | None, warnings, facts) of a parsed log, whole (pure)."""
    p = plan(parse, topic, label)
    runs, poses = [], []
    for run, odom in blocks(parse, p, max(p.stream.count, 1)):
        if run is not None:
            runs.append(run)
        if odom is not None:
            poses.append(odom)
    run = (
        runs[0]
        if len(runs) == 1
        else ScanRun(
            np.concatenate([r.stamps for r in runs]),
            np.concatenate([r.ranges for r in runs]),
            p.geometry,
            np.concatenate([r.intensities for r in runs]),
        )
    )
    return run, _cat(poses) if poses else None, p.warnings, p.facts


MAX_LINE = 1 << 20  # characters of a line: a laser line of 10,000 beams and remissions takes under 200,000
_TOO_LONG = "<a line longer than MAX_LINE>"  # what a longer line is read as: a malformed line (not a message name)


def _lines(f, progress, raw, total: int, label: str, warnings: list[str]):
    """Lines of a text stream, each read in at most MAX_LINE characters (a longer one, skipped in pieces of that
    size, comes out as _TOO_LONG: memory does not grow with a line's length, e.g. a gigabyte without a newline
    in a .log.gz); reports progress by compressed bytes; a truncated gzip stream ends the lines with a warning
    instead of an error."""
    step = 0
    try:
        while line := f.readline(MAX_LINE):
            step += 1
            if progress is not None and step % 20000 == 0:
                progress(raw.tell(), total)
            if len(line) == MAX_LINE and not line.endswith("\n"):
                while (rest := f.readline(MAX_LINE)) and not rest.endswith("\n"):
                    pass
                line = _TOO_LONG
            yield line
    except EOFError:
        warnings.append(f"{label}: gzip stream ends early (truncated file); read {step} lines before the cut")


def stream_carmen(
    path: str | Path,
    *,
    topic: str | None = None,
    max_scans: int | None = None,
    progress=None,
    spool_dir: str | Path | None = None,
    block_scans: int = 1024,
):
    """ImportStream of a CARMEN (or g2o ROBOTLASER1) text log, plain or gzipped.

    One pass parses the text and spools the scans to a temporary folder in `spool_dir` (the system's
    when None), keeping only counts and whole-log figures (no-return limit, stamp checks); the stream's
    blocks then read the spool `block_scans` scans at a time. Memory holds one block whatever the log's
    length (and, for a log whose stamps are synthesised, its stamps while counting the distinct ones).
    """
    import io
    import tempfile

    from .stream import ImportStream

    path = Path(path)
    label = str(path)
    total = path.stat().st_size
    io_warnings: list[str] = []
    try:
        spool = tempfile.TemporaryDirectory(prefix=".datmo-import-", dir=spool_dir)
    except OSError as exc:
        raise DatmoError(
            f"{spool_dir or tempfile.gettempdir()}: cannot make a temporary folder for the parsed "
            f"scans ({exc.strerror or exc})"
        ) from None
    try:
        with open(path, "rb") as raw:
            gz = raw.read(2) == b"\x1f\x8b"
            raw.seek(0)
            binary = gzip.GzipFile(fileobj=raw) if gz else raw
            text = io.TextIOWrapper(binary, encoding="utf-8", errors="replace", newline=None)
            try:
                parse = parse_lines(
                    _lines(text, progress, raw, total, label, io_warnings),
                    topic=topic,
                    max_scans=max_scans,
                    spool=Path(spool.name),
                )
            except GeometryError as exc:
                raise GeometryError(f"{label}: {exc}") from None
        if progress is not None:
            progress(total, total)
        if parse.lines == 0:
            raise InputError(f"{label}: empty file (no lines)")
        p = plan(parse, topic, label)
    except OSError as exc:  # the disk full while spooling, or the input unreadable
        spool.cleanup()
        raise DatmoError(
            f"{label}: {exc.strerror or exc} (reading it, or spooling its scans to {Path(spool.name).parent})"
        ) from None
    except BaseException:
        spool.cleanup()
        raise
    p.facts["params"] = {k: v for k, v in parse.params.items() if k.startswith(("laser_", "robot_front_laser"))}

    def pieces() -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        try:
            yield from blocks(parse, p, block_scans)
        finally:
            spool.cleanup()

    return ImportStream(
        pieces(),
        warnings=io_warnings + p.warnings,
        topic=p.stream.name,
        odom_topic=p.odometry_source,
        facts=p.facts,
        geometry=p.geometry,
        closer=spool.cleanup,
    )
