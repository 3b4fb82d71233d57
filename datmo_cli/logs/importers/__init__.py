"""Importers: real logs from other tools into a ScanRun (and Odometry) that `datmo import` writes.

Supported kinds (see `detect_kind`):

- ``carmen``: CARMEN text logs (FLASER, RLASER, RAWLASER1-4, ROBOTLASER1-2; plain or gzipped),
- ``g2o``: g2o files carrying CARMEN ROBOTLASER1 lines (e.g. MIT Killian Court), read like CARMEN,
- ``ros1``: ROS 1 bags, ``ros2``: ROS 2 bag folders (sqlite3 or mcap storage), both via rosbags,
- ``mcap``: a single MCAP file with CDR sensor_msgs/msg/LaserScan (ROS 2 style, datmo's own included).

Every importer opens an ImportStream: what is known of the source up front, then its scans and poses in
blocks of about IMPORT_BLOCK scans, in time order; `write_import` writes them block by block (through
log.ordered.OrderedSink), so `datmo import` holds one block whatever the log's length, and `import_log`
collects them into an ImportResult (the whole run, for tests and tools that want arrays). Bad input
raises datmo_cli.base.errors.InputError with a one-line message naming the file and the problem.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from ...base.errors import InputError
from ..scan import Odometry, ScanGeometry, ScanRun
from .stream import ImportResult, ImportStream, compressed_errors

#: progress(done, total): bytes of a text log, or messages of a bag, read so far (total 0 when unknown).
Progress = Callable[[int, int], None]

IMPORT_BLOCK = 1024  # scans per block
KINDS = ("carmen", "g2o", "ros1", "ros2", "mcap")
_ROSBAG1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP"
_GZIP_MAGIC = b"\x1f\x8b"


def _check_path(path: Path) -> None:
    from ...base.input_files import check

    check(path, folder_ok=True)  # a regular file or a folder: a FIFO or a device would never end
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return
        raise InputError(f"{path}: is a directory, not a log (a ROS 2 bag folder holds metadata.yaml)")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")


def _head(path: Path, size: int = 65536) -> bytes:
    """The first `size` bytes of the file's content (decompressed when gzipped)."""
    with open(path, "rb") as f:
        raw = f.read(size)
    if raw.startswith(_GZIP_MAGIC):
        try:
            return zlib.decompressobj(16 + zlib.MAX_WBITS).decompress(raw, size)
        except zlib.error as exc:
            raise InputError(f"{path}: corrupt gzip data ({exc})") from None
    return raw


def detect_kind(path: str | Path) -> str:
    """The kind of log at `path` (one of KINDS), judged by content, not by name.

    Raises InputError for a missing file, an empty file, a directory that is not a ROS 2 bag, and
    content of no known kind.
    """
    from .carmen_parse import sniff_text

    path = Path(path)
    _check_path(path)
    if path.is_dir():
        return "ros2"
    head = _head(path)
    if not head:
        raise InputError(f"{path}: empty file (nothing after decompression)")
    if head.startswith(_ROSBAG1_MAGIC):
        return "ros1"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    kind = sniff_text(head)
    if kind is None:
        raise InputError(f"{path}: unknown kind of file (not a CARMEN or g2o text log, ROS bag or MCAP)")
    return kind


def open_import(
    path: str | Path,
    topic: str | None = None,
    *,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    progress: Progress | None = None,
    spool_dir: str | Path | None = None,
    block_scans: int | None = None,
) -> ImportStream:
    """Open the log at `path` for importing block by block (see ImportStream).

    topic: which scan stream to take when there are several (a ROS topic, or for CARMEN a message name
    such as FLASER or ROBOTLASER1); odom_topic: the nav_msgs/Odometry topic of a bag (default: the only
    one, if any); max_scans: keep only the first N scans (and the poses up to the last one kept);
    spool_dir: where a text log's parsed scans wait for the whole-log checks (the system's temporary
    folder when None; `datmo import` gives the output's folder); block_scans: scans per block (IMPORT_BLOCK).
    """
    path = Path(path)
    block_scans = block_scans or IMPORT_BLOCK
    kind = detect_kind(path)
    if max_scans is not None and max_scans < 1:
        raise InputError(f"{path}: --max-scans must be at least 1")
    with compressed_errors(path):
        if kind in ("carmen", "g2o"):
            from .carmen import stream_carmen

            stream = stream_carmen(
                path, topic=topic, max_scans=max_scans, progress=progress, spool_dir=spool_dir, block_scans=block_scans
            )
        elif kind == "mcap":
            from .mcap_file import stream_mcap

            stream = stream_mcap(path, topic=topic, odom_topic=odom_topic, max_scans=max_scans, block_scans=block_scans)
        else:
            from .rosbag import stream_bag

            stream = stream_bag(
                path,
                topic=topic,
                odom_topic=odom_topic,
                max_scans=max_scans,
                progress=progress,
                block_scans=block_scans,
            )
    stream.kind = kind
    stream.source = path
    return stream


def import_log(
    path: str | Path,
    topic: str | None = None,
    *,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    progress: Progress | None = None,
) -> ImportResult:
    """Read the log at `path` into arrays: open_import's blocks collected (arguments as there)."""
    return open_import(path, topic, odom_topic=odom_topic, max_scans=max_scans, progress=progress).collect()


@dataclass
class ImportStats:
    """What write_import wrote, and the most it held: scans in a block, messages in its time-order window."""

    scans: int
    poses: int
    geometry: ScanGeometry | None
    late: int
    peak_scans: int
    peak_messages: int


def write_import(
    stream: ImportStream,
    output: str | Path,
    *,
    force: bool = False,
    provenance=None,
    window: int | None = None,
    laser_pose=None,
) -> ImportStats:
    """Write `stream`'s scans to /scan and poses to /odom of `output` (atomically, LogWriter), block by block
    in time order (OrderedSink over `window` messages), with the transforms (see Frames), then its facts as
    metadata "datmo.import". Raises InputError when there are no scans. A message more than the window late is
    written out of order with a warning added to stream.warnings; so is a warning for scans that came out of time
    order (written in time order) or repeat a stamp (dropped, the first kept), as collect() does.
    `laser_pose`: a transforms.LaserPose, where the scanner sits on the base (None: not given)."""
    from .. import mcapio, types
    from ..ordered import WINDOW, OrderedSink, order_note

    window = window or WINDOW
    src = stream.source
    scans = poses = 0
    geometry = None
    try:
        with mcapio.LogWriter(output, force=force, provenance=provenance) as writer:
            scan_cid, odom_cid = writer.channel(mcapio.TOPIC_SCAN, types.LASERSCAN), None
            sink = OrderedSink(writer, window, unique=(scan_cid,))
            frames = Frames(stream, writer, sink, laser_pose)
            for run, odom in stream.blocks():
                if run is not None and len(run):
                    geometry = geometry or run.geometry
                    frames.scans(run)
                    sink.add(scan_cid, run.stamps, mcapio.encode_scans(run))
                    scans += len(run)
                if odom is not None and len(odom):
                    if odom_cid is None:
                        odom_cid = writer.channel(mcapio.TOPIC_ODOM, types.ODOMETRY)
                    odom = frames.poses(odom)
                    sink.add(odom_cid, odom.stamps, mcapio.encode_odometry(odom))
                    poses += len(odom)
                frames.copy()
                sink.flush()
            if scans == 0:
                raise InputError(f"{src}: no scans to write")
            sink.close()
            note = order_note(src, scans, sink.reordered, sink.first_reordered, sink.dropped, sink.first_dropped)
            if note:
                stream.warnings.append(note)
            scans -= sink.dropped
            if sink.late:
                stream.warnings.append(
                    f"{src}: {sink.late} message{'s' if sink.late != 1 else ''} came after later "
                    f"ones beyond a window of {window}; written out of time order"
                )
            writer.add_metadata("datmo.import", import_facts(stream))
            if laser_pose is not None:
                from ..transforms import BASE_FRAME, LASER_POSE_RECORD

                assert geometry is not None  # scans == 0 was refused above
                writer.add_metadata(LASER_POSE_RECORD, laser_pose.record(BASE_FRAME, geometry.frame_id))
    finally:
        stream.close()
    return ImportStats(scans, poses, geometry, sink.late, stream.peak_scans, sink.peak)


class Frames:
    """The transforms of an import: every log with poses gets `odom -> base -> laser` (the poses' frame, their
    child frame, the scan's frame), whatever the source gave.

    - The source's own /tf and /tf_static are kept (a ROS 1 tf/tfMessage or tf2_msgs/TFMessage converted to
      tf2_msgs/msg/TFMessage), frame names without ROS 1's leading slash. /tf is derived from the poses (one
      transform a pose, frame_id -> child_frame_id) when the source has none.
    - The mount `base -> laser` on /tf_static, for each child frame of the poses: the laser pose when one is
      given (--laser-pose); else nothing when the source's /tf_static joins the two frames; else the source's
      /tf transforms that join them and never change (a ROS 1 robot repeats its mount on /tf), copied to
      /tf_static; else the identity, with a one-line warning saying how to give --laser-pose.
    - Poses of the scanner itself (child frame = the scan's, as CARMEN's laser poses) become the base's, child
      base_link: under the laser pose when given, else under the identity (the same numbers), with that warning.
    - A laser pose without poses: `base_link -> laser` on /tf_static."""

    def __init__(self, stream: ImportStream, writer, sink, laser_pose) -> None:
        from .. import mcapio

        self.stream, self.writer, self.sink, self.mount = stream, writer, sink, laser_pose
        self.keep_tf = mcapio.TOPIC_TF in stream.tf_topics
        self.ids: dict[str, int] = {}
        self.laser: str | None = None  # the scan's frame, once a scan came
        self.first: int | None = None  # the first scan's stamp
        self.joined: set[str] = set()  # child frames of the poses whose mount is settled
        self.pending: list = []  # poses' child frames (and stamps) waiting for the first scan
        self.warned = False

    def _cid(self, topic: str) -> int:
        from .. import mcapio

        if topic not in self.ids:
            self.ids[topic] = self.writer.transform_channel(static=topic == mcapio.TOPIC_TF_STATIC)
        return self.ids[topic]

    def _static(self, stamp: int, parent: str, pose) -> None:
        from .. import transforms

        assert self.laser is not None  # the scan's frame: after the first scan
        self._write_static(stamp, [transforms.Transform.planar(stamp, parent, self.laser, pose.x, pose.y, pose.yaw)])

    def _write_static(self, stamp: int, found: list) -> None:
        from .. import mcapio, transforms

        self.sink.add(self._cid(mcapio.TOPIC_TF_STATIC), [stamp], [transforms.encode_tf(found)])

    def _no_mount(self, base: str, laser: str, how: str = "wrote the identity") -> None:
        self.stream.facts["laser_pose"] = "identity (none found)"
        if self.warned:
            return
        self.warned = True
        self.stream.warnings.append(
            f"{self.stream.source}: no laser mount ({base} -> {laser}) in the log; {how}: "
            "give the scanner's mounting with --laser-pose X,Y,YAW (metres, metres, degrees)"
        )

    def scans(self, run: ScanRun) -> None:
        """A block of scans: the first fixes the scan's frame (and writes what waited for it)."""
        from .. import transforms

        if self.laser is not None:
            return
        self.laser, self.first = run.geometry.frame_id, int(run.stamps[0])
        if self.mount is not None and self.stream.odom_topic is None:
            self.joined.add(transforms.BASE_FRAME)
            self._static(self.first, transforms.BASE_FRAME, self.mount)
        for child, stamp in self.pending:
            self._tie(child, stamp)
        self.pending = []

    def _tie(self, child: str, stamp: int) -> None:
        from .. import transforms

        if child in self.joined or child == self.laser:
            return
        assert self.laser is not None and self.first is not None  # scans() ties only once a scan came
        self.joined.add(child)
        at = min(stamp, self.first)
        if self.mount is not None:
            self._static(at, child, self.mount)
            return
        survey = self.stream.tf_survey
        statics = survey.statics if survey is not None else []
        if transforms.chain(statics, child, self.laser) is not None:
            self.stream.facts["laser_pose"] = "/tf_static"
            return
        links = transforms.chain(survey.constant + statics, child, self.laser) if survey is not None else None
        if links is not None:
            self.stream.facts["laser_pose"] = "/tf (constant there)"
            self._write_static(at, [replace(t, stamp_ns=at) for t in links if t not in statics])
            return
        self._no_mount(child, self.laser)
        self._static(at, child, transforms.LaserPose())

    def poses(self, odom: Odometry) -> Odometry:
        """A block of poses as written to /odom, their /tf written unless the source has its own."""
        from .. import mcapio, transforms

        laser = self.laser
        if laser is None and self.stream.geometry is not None:  # poses before the first scan
            laser = self.stream.geometry.frame_id
        if odom.child_frame_id == laser:
            if self.mount is not None:
                odom = transforms.base_odometry(odom, self.mount)
            else:  # the identity mount: the same poses, the base's
                self._no_mount(transforms.BASE_FRAME, laser, "the poses are the scanner's, so the base is put on it")
                odom = Odometry(odom.stamps, odom.x, odom.y, odom.theta, odom.frame_id, transforms.BASE_FRAME)
        if not self.keep_tf:
            self.sink.add(self._cid(mcapio.TOPIC_TF), odom.stamps, transforms.odometry_tf(odom))
        if self.laser is None:
            self.pending.append((odom.child_frame_id, int(odom.stamps[0])))
        else:
            self._tie(odom.child_frame_id, int(odom.stamps[0]))
        return odom

    def copy(self) -> None:
        """The source's transforms read with the last block."""
        for topic, stamp, payload in self.stream.transforms:
            self.sink.add(self._cid(topic), [stamp], [payload])
        self.stream.transforms.clear()


def import_facts(stream: ImportStream) -> dict[str, str]:
    """The "datmo.import" metadata of an import."""
    import json

    out = {
        "kind": stream.kind,
        "topic": str(stream.topic),
        "odom_topic": str(stream.odom_topic or ""),
        "source": str(stream.source),
        "warnings": json.dumps(stream.warnings),
    }
    out.update({k: json.dumps(v, default=str) for k, v in stream.facts.items()})
    return out


__all__ = [
    "IMPORT_BLOCK",
    "KINDS",
    "ImportResult",
    "ImportStats",
    "ImportStream",
    "detect_kind",
    "import_facts",
    "import_log",
    "open_import",
    "write_import",
]
