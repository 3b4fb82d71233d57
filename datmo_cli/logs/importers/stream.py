"""An opened import source (ImportStream: blocks of scans and poses in time order) and what collecting it gives
(ImportResult: the whole run as arrays)."""

from __future__ import annotations

import gzip
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ...base.errors import InputError
from ..scan import Odometry, ScanGeometry, ScanRun

if TYPE_CHECKING:
    from .ros_messages import TfSurvey


@dataclass
class ImportResult:
    """What an importer made of a source log.

    run: the scans (ranges in metres, sensor frame; +inf = no return); odometry: poses of the sensor
    in the world/odom frame at the scan stamps (or from the source's odometry topic), or None;
    warnings: one-line notes for the user (skipped lines, synthesised stamps, ...); kind: one of KINDS;
    topic: the source's name of the scan stream (a ROS topic, or a CARMEN message name such as FLASER);
    odom_topic: the source of the poses, or None; facts: small JSON-ready details (counts, conventions).
    """

    run: ScanRun
    odometry: Odometry | None
    warnings: list[str] = field(default_factory=list)
    kind: str = ""
    topic: str = ""
    odom_topic: str | None = None
    source: Path | None = None
    facts: dict = field(default_factory=dict)


class compressed_errors:
    """Corrupt or truncated compressed data as a one-line InputError naming the file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> None:
        return None

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and issubclass(exc_type, (EOFError, gzip.BadGzipFile, zlib.error)):
            raise InputError(f"{self.path}: corrupt or truncated compressed data ({exc})") from None


@dataclass
class ImportStream:
    """An opened source: kind, topic, odometry source, warnings and facts as known up front, then `blocks()`:
    (scans, poses) pieces (either may be None) in time order, about `block_scans` scans at a time. Warnings
    and facts are complete once the blocks are done. `peak_scans`: the most scans a piece held."""

    pieces: Iterator[tuple[ScanRun | None, Odometry | None]]
    warnings: list[str] = field(default_factory=list)
    kind: str = ""
    topic: str = ""
    odom_topic: str | None = None
    source: Path | None = None
    facts: dict = field(default_factory=dict)
    geometry: ScanGeometry | None = None
    sort_odometry: bool = False  # collect() sorts the poses by stamp (what the whole-run bag import did)
    closer: Callable[[], None] | None = None  # releases what the source holds open, when blocks() is not run
    peak_scans: int = 0
    # the source's /tf and /tf_static: (topic, log time ns, CDR TFMessage payload) read with the last block, taken
    # by write_import; `tf_topics` those it has (known up front)
    transforms: list[tuple[str, int, bytes]] = field(default_factory=list)
    tf_topics: tuple[str, ...] = ()
    # a source with poses and transforms: its /tf_static and its /tf transforms that never change (TfSurvey)
    tf_survey: TfSurvey | None = None

    def blocks(self) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        """The pieces, each piece's poses without those not finite or beyond poses.MAX_POSE_M (counted in one
        warning once the pieces are done)."""
        from .. import poses

        seen, dropped, first = 0, 0, -1
        with compressed_errors(self.source or Path("?")):
            for scans, odom in self.pieces:
                if scans is not None:
                    self.peak_scans = max(self.peak_scans, len(scans))
                if odom is not None and len(odom):
                    n = len(odom)
                    odom, bad, at = poses.keep_sane(odom)
                    if bad and first < 0:
                        first = seen + at
                    seen, dropped = seen + n, dropped + bad
                yield scans, odom
        if dropped:
            self.warnings.append(poses.note(self.source or self.topic, dropped, seen, first))

    def close(self) -> None:
        """Stop early (temporary files removed, readers closed)."""
        close = getattr(self.pieces, "close", None)
        if close is not None:
            close()
        if self.closer is not None:
            self.closer()

    def collect(self) -> ImportResult:
        """The whole run as one ImportResult: its scans in time order, a scan that repeats the stamp of
        one before it dropped, with the warning write_import gives."""
        import numpy as np

        runs, poses = [], []
        for scans, odom in self.blocks():
            if scans is not None and len(scans):
                runs.append(scans)
            if odom is not None and len(odom):
                poses.append(odom)
        if runs:
            from ..ordered import order_note, stamp_order

            g = runs[0].geometry
            stamps = np.concatenate([r.stamps for r in runs])
            keep, reordered, first_reordered, dropped, first_dropped = stamp_order(stamps)
            note = order_note(self.source, len(stamps), reordered, first_reordered, dropped, first_dropped)
            if note:  # as write_import writes them: in time order, a repeated stamp dropped
                self.warnings.append(note)
            run = ScanRun(
                stamps[keep],
                np.concatenate([r.ranges for r in runs])[keep],
                g,
                np.concatenate([r.intensities for r in runs])[keep],
            )
        else:
            g = self.geometry or ScanGeometry(0.0, 0.0, 0, 0.0, 0.0)
            run = ScanRun(np.zeros(0, np.int64), np.zeros((0, g.n_beams), np.float32), g)
        odometry = None
        if poses:
            cols = [np.concatenate([getattr(o, f) for o in poses]) for f in ("stamps", "x", "y", "theta")]
            if self.sort_odometry:
                order = np.argsort(cols[0], kind="stable")
                cols = [c[order] for c in cols]
            stamps_, x, y, theta = cols
            odometry = Odometry(stamps_, x, y, theta, poses[-1].frame_id, poses[-1].child_frame_id)
        return ImportResult(
            run=run,
            odometry=odometry,
            warnings=self.warnings,
            kind=self.kind,
            topic=self.topic,
            odom_topic=self.odom_topic,
            source=self.source,
            facts=self.facts,
        )
