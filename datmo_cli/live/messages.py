"""What the live view publishes: a Message (log time, topic, ROS 2 type, CDR payload), the transforms a log
lacks (Transforms: odom -> base_link at each scan on /tf, base_link -> the scan's frame on /tf_static), and the
stages' messages of scans as they come (Stages)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..logs.scan import Odometry, ScanGeometry, ScanRun
from ..logs.transforms import Transform, encode_tf

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STATIC_EVERY_NS = 1_000_000_000  # static transforms are sent again after this much log time


@dataclass(frozen=True)
class Message:
    """One message to publish: its time (the header stamp, ns), topic, ROS 2 type and CDR payload."""

    stamp: int
    topic: str
    msgtype: str
    payload: bytes


def tf_payload(stamp: int, transforms: Iterable[tuple[str, str, float, float, float]]) -> bytes:
    """CDR of a tf2_msgs/msg/TFMessage stamped `stamp` (ns) holding `transforms`: (parent frame, child
    frame, x m, y m, yaw rad) each, in the plane."""
    return encode_tf([Transform.planar(stamp, parent, child, x, y, yaw) for parent, child, x, y, yaw in transforms])


class Transforms:
    """The transforms a log lacks, scan by scan: with odometry, odom -> base_link at each scan's stamp
    (/tf) and base_link -> the scan's frame, identity, when the two differ (/tf_static, every second of log
    time). Nothing when the log has /tf of its own or no odometry."""

    def __init__(self, odometry: Odometry | None, scan_frame: str, has_own: bool) -> None:
        self.odometry = odometry if odometry is not None and len(odometry) and not has_own else None
        self.scan_frame = scan_frame
        self._static_at: int | None = None

    def topics(self) -> dict[str, str]:
        """{topic: message type} of what `messages` gives (to advertise them before the first)."""
        if self.odometry is None:
            return {}
        static = self.odometry.child_frame_id != self.scan_frame
        return {TOPIC_TF: TF_MESSAGE} | ({TOPIC_TF_STATIC: TF_MESSAGE} if static else {})

    def messages(self, stamps: np.ndarray) -> list[Message]:
        o = self.odometry
        if o is None or not len(stamps):
            return []
        out = []
        static = o.child_frame_id != self.scan_frame
        for stamp, (x, y, yaw) in zip(stamps.tolist(), o.at(stamps).tolist(), strict=True):
            if static and (
                self._static_at is None or stamp - self._static_at >= STATIC_EVERY_NS or stamp < self._static_at
            ):
                out.append(
                    Message(
                        stamp,
                        TOPIC_TF_STATIC,
                        TF_MESSAGE,
                        tf_payload(stamp, [(o.child_frame_id, self.scan_frame, 0.0, 0.0, 0.0)]),
                    )
                )
                self._static_at = stamp
            out.append(
                Message(stamp, TOPIC_TF, TF_MESSAGE, tf_payload(stamp, [(o.frame_id, o.child_frame_id, x, y, yaw)]))
            )
        return out


class Stages:
    """Segmentation, features and tracking of scans as they come (pipeline.RunStages, its state carried from
    call to call): `messages(run)` gives the derived messages of the next scans, with the transforms."""

    def __init__(
        self,
        odometry: Odometry | None,
        geometry: ScanGeometry,
        config: DatmoConfig | None = None,
        estimated: bool = False,
        has_tf: bool = False,
    ) -> None:
        from ..passes.pipeline import RunStages

        self.stages = RunStages(odometry, geometry, config, estimated=estimated)
        self.derived = self.stages.derived()
        self.transforms = Transforms(odometry, geometry.frame_id, has_tf or TOPIC_TF in self.derived)
        self.first = 0

    def messages(self, run: ScanRun) -> list[Message]:
        from ..passes.streaming import Block

        out = self.transforms.messages(run.stamps)
        for topic, (msgtype, stamps, payloads) in self.stages(Block(self.first, run)).items():
            out += [Message(int(s), topic, msgtype, bytes(p)) for s, p in zip(stamps, payloads, strict=True)]
        self.first += len(run)
        return out
