"""`datmo import`'s work as a call (datmo_cli.api.import_log): a CARMEN log, g2o file, ROS 1/2 bag or MCAP file
converted to a datmo scan log (logs.importers: /scan in metres, "no return" as +inf, the sensor frame of the
source; poses on /odom in the odometry frame, with /tf and /tf_static), with the import's provenance. The command
keeps what it prints: the summary line and the importer's warnings (said as Python warnings here)."""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..logs.importers import ImportStats


@dataclass
class ImportResult:
    """What an import wrote: `output`, the source's `kind` ("carmen", "g2o", "ros1", "ros2", "mcap"), the scan
    `topic` taken and the `odom_topic` (None: no poses), and the importer's `stats` (.scans, .poses, .geometry:
    the scans' ScanGeometry, angles in radians and ranges in metres, or None without scans); `warnings`: the
    malformed lines skipped and the like (also given as Python warnings)."""

    output: Path
    kind: str
    topic: str | None
    odom_topic: str | None
    stats: ImportStats
    warnings: list[str] = field(default_factory=list)

    @property
    def scans(self) -> int:
        return self.stats.scans

    @property
    def poses(self) -> int:
        return self.stats.poses

    @property
    def summary(self) -> str:
        """The line `datmo import` says: the output, its scans, their geometry, the source and the poses."""
        odom = f", {self.stats.poses} poses on /odom" if self.stats.poses else ""
        geometry = self.stats.geometry.describe() if self.stats.geometry is not None else "no geometry"
        return f"{self.output}: {self.stats.scans} scans of {geometry} from {self.kind} {self.topic}{odom}"


def import_log(
    src: str | os.PathLike,
    output: str | os.PathLike,
    *,
    force: bool = False,
    topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    laser_pose: tuple[float, float, float] | None = None,
    command_line: str | None = None,
) -> ImportResult:
    """`datmo import SRC -o OUTPUT`: convert `src` (its kind found from its content) into the MCAP log `output`
    (refused when it exists, unless `force`; written under a temporary name and renamed when complete).
    `topic`: the scan stream to take when there are several (a LaserScan topic, or a CARMEN message name such
    as FLASER); `odom_topic`: the nav_msgs/Odometry topic of a bag or MCAP; `max_scans`: keep the first N
    scans; `laser_pose` (x m, y m, yaw rad): the scanner's mount on the robot, for sources whose poses are
    the scanner's (CARMEN's), which then become the base's. A progress bar on stderr in a terminal for inputs
    over 20 MB. `command_line` goes into the provenance. Returns the ImportResult; InputError (one line naming
    the file) for an input that cannot be read."""
    from ..base.outputs import check_output
    from ..logs import mcapio
    from ..logs.importers import open_import, write_import

    src, output = Path(src), Path(output)
    check_output(output, force=force, inputs=[src])  # before reading a big input
    if command_line is None:
        command_line = f"datmo_cli.api.import_log({os.fsdecode(src)!r}, {os.fsdecode(output)!r})"
    with _progress(src) as progress:
        stream = open_import(
            src,
            topic,
            odom_topic=odom_topic,
            max_scans=max_scans,
            progress=progress,
            spool_dir=output.parent if output.parent.is_dir() else None,
        )
        params: dict[str, object] = {
            "topic": stream.topic,
            "odom_topic": stream.odom_topic,
            "max_scans": max_scans,
            "kind": stream.kind,
        }
        mount = None
        if laser_pose is not None:
            from ..logs.transforms import LaserPose

            mount = LaserPose(*laser_pose)
            params["laser_pose"] = {"x_m": mount.x, "y_m": mount.y, "yaw_deg": math.degrees(mount.yaw)}
        provenance = mcapio.Provenance("import", params, [src] if src.is_file() else [], command_line)
        try:
            stats = write_import(stream, output, force=force, provenance=provenance, laser_pose=mount)
        finally:
            for w in stream.warnings:
                warnings.warn(w, stacklevel=2)
    return ImportResult(output, stream.kind, stream.topic, stream.odom_topic, stats, list(stream.warnings))


@contextlib.contextmanager
def _progress(src: Path) -> Iterator[Callable[[int, int], None] | None]:
    """A progress callback (done, total) drawing a bar on stderr for inputs over 20 MB, else None. The
    total is the bytes of a text log or the messages of a bag, as the importer counts them."""
    from ..logs.importers import detect_kind

    size = src.stat().st_size if src.is_file() else 0
    if size < 20_000_000:
        yield None
        return
    from ..base.progress import bar

    unit = "messages" if detect_kind(src) in ("ros1", "ros2", "mcap") else "bytes"
    with bar(f"reading {src.name}", None, unit=unit) as progress:
        yield lambda done, total: progress.update(done, total or None)
