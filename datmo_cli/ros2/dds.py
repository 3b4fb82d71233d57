"""ROS 2 topics over DDS without ROS: Eclipse Cyclone DDS's Python binding (`cyclonedds`, the node extra) used
with the conventions rmw_cyclonedds_cpp (ROS 2's Cyclone DDS middleware) puts on the wire.

- A ROS 2 topic `/name` is the DDS topic `rt/name`; its type `pkg/msg/Type` is the DDS type
  `pkg::msg::dds_::Type_`, a final struct of the .msg's fields (datmo_msgs from datmo_cli/msg, the others
  from the ROS 2 Humble definitions rosbags ships), so peers that send XTypes type information match.
- Samples are plain CDR, little endian (XCDR1, the data representation ROS 2 asks for): byte for byte the
  payloads datmo writes to MCAP, padded with zeros to a multiple of 4 bytes as DDS sends them.
- QoS: publications use ROS 2's default profile (reliable, volatile, keep last 10); subscriptions are best
  effort (ROS 2's sensor-data profile), which matches a reliable or a best-effort publisher alike.
- The domain is ROS_DOMAIN_ID's (0 when unset); the network, Cyclone DDS's own configuration (CYCLONEDDS_URI).

Payloads go in and out as bytes (`CdrWriter.write`, `CdrReader.take`): the codecs are datmo's own (log/), the
same that read and write the log files.
"""

from __future__ import annotations

import os
import re
import types as pytypes
from dataclasses import dataclass
from functools import cache

from ..base.errors import ConfigError
from ..base.extras import require
from ..logs import types

DOMAIN_ID_MAX = 232  # ROS 2 domain ids: 0-232 (the DDS port mapping runs out above)
DEFAULT_DEPTH = 10  # ROS 2's default history depth
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_PADDING = 4  # a DDS sample's size is a multiple of this (bytes)


def require_cyclonedds():
    """The cyclonedds module (with the parts used here loaded), or MissingExtraError naming the node extra."""
    for module in (
        "cyclonedds.domain",
        "cyclonedds.topic",
        "cyclonedds.pub",
        "cyclonedds.sub",
        "cyclonedds.core",
        "cyclonedds.qos",
        "cyclonedds.idl",
    ):
        require(module, for_="datmo node")
    return require("cyclonedds", for_="datmo node")


def ros_topic(name: str, option: str = "topic") -> str:
    """The absolute ROS 2 name of topic `name` ('/scan', or 'scan' taken from the root namespace); ConfigError
    naming `option` for a name ROS 2 would refuse (tokens of letters, digits and underscores, not starting with
    a digit, separated by single slashes)."""
    tokens = name.removeprefix("/").split("/")
    if not all(_NAME.fullmatch(t) for t in tokens):
        raise ConfigError(
            f"{option} {name!r}: not a ROS 2 topic name (letters, digits and underscores between "
            "single slashes, each part not starting with a digit)"
        )
    return "/" + "/".join(tokens)


def dds_topic(name: str) -> str:
    """The DDS topic of ROS 2 topic `name` (absolute): '/scan' -> 'rt/scan'."""
    return "rt" + name


def dds_type_name(msgtype: str) -> str:
    """The DDS type name of ROS 2 type `msgtype`: 'sensor_msgs/msg/LaserScan' ->
    'sensor_msgs::msg::dds_::LaserScan_'."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def domain_id(value: int | None = None) -> int:
    """The DDS domain: `value` when given, else ROS_DOMAIN_ID (0 when unset); ConfigError when out of 0-232."""
    if value is None:
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        try:
            value = int(text) if text else 0
        except ValueError:
            raise ConfigError(f"ROS_DOMAIN_ID {text!r}: not an integer (0 to {DOMAIN_ID_MAX})") from None
        source = "ROS_DOMAIN_ID"
    else:
        source = "--domain-id"
    if not 0 <= value <= DOMAIN_ID_MAX:
        raise ConfigError(f"{source} {value}: a ROS 2 domain id is 0 to {DOMAIN_ID_MAX}")
    return value


# ------------------------------------------------------------------------------------------ IDL types


def _base(kind: str):
    from cyclonedds.idl import types as t

    return {
        "bool": bool,
        "byte": t.byte,
        "char": t.uint8,
        "int8": t.int8,
        "uint8": t.uint8,
        "int16": t.int16,
        "uint16": t.uint16,
        "int32": t.int32,
        "uint32": t.uint32,
        "int64": t.int64,
        "uint64": t.uint64,
        "float32": t.float32,
        "float64": t.float64,
        "string": str,
    }[kind]


def _annotation(spec: tuple):
    """The cyclonedds annotation of a field spec; bounds kept (string<=256, Type[<=1]) as the .msg says."""
    from cyclonedds.idl import types as t

    node, detail = spec
    if node == types.BASE:
        return t.bounded_str[detail[1]] if detail[0] == "string" and detail[1] else _base(detail[0])
    if node == types.NAME:
        return idl_class(detail)
    if node == types.ARRAY:
        return t.array[_annotation(detail[0]), detail[1]]
    if node == types.SEQUENCE:
        return t.sequence[_annotation(detail[0]), detail[1]] if detail[1] else t.sequence[_annotation(detail[0])]
    raise ValueError(f"field kind {node} of a ROS 2 message is not known")


@cache
def idl_class(msgtype: str) -> type:
    """The cyclonedds IdlStruct of ROS 2 type `msgtype`, named as rmw_cyclonedds names it, its fields those of
    the type's .msg definition in order (nested types likewise)."""
    require_cyclonedds()
    from cyclonedds.idl import IdlStruct

    annotations = {name: _annotation(spec) for name, spec in types.fields(msgtype)}

    def body(namespace: dict) -> None:
        namespace["__annotations__"] = annotations
        namespace["__module__"] = __name__

    cls = pytypes.new_class(msgtype.replace("/", "_"), (IdlStruct,), {"typename": dds_type_name(msgtype)}, body)
    return dataclass(cls)


# -------------------------------------------------------------------------------------- QoS and endpoints


def publication_qos(depth: int = DEFAULT_DEPTH):
    """ROS 2's default QoS profile (reliable, volatile, keep last `depth`), in XCDR1."""
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    return Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )


def subscription_qos(depth: int = DEFAULT_DEPTH):
    """ROS 2's sensor-data profile, best effort (it matches reliable and best-effort publishers), volatile,
    keep last `depth`, in XCDR1."""
    from cyclonedds.qos import Policy, Qos

    return Qos(
        Policy.Reliability.BestEffort,
        Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )


def qos(
    reliable: bool = True,
    transient_local: bool = False,
    depth: int = DEFAULT_DEPTH,
    lifespan_s: float = 0.0,
    userdata: bytes = b"",
):
    """A QoS in ROS 2's terms: reliable or best effort, transient-local or volatile, keep last `depth`, a
    lifespan of `lifespan_s` seconds (0: infinite), in XCDR1, with `userdata` (none when empty)."""
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    policies = [
        Policy.Reliability.Reliable(duration(milliseconds=100)) if reliable else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if lifespan_s > 0:
        policies.append(Policy.Lifespan(duration(seconds=lifespan_s)))
    if userdata:
        policies.append(Policy.Userdata(userdata))
    return Qos(*policies)


def gid(entity, size: int) -> bytes:
    """The ROS 2 GID of a DDS entity as rmw_cyclonedds_cpp makes it: the entity's 16-byte DDS GUID, padded
    with zeros to `size` bytes (24 in ROS 2 Humble's rmw_dds_common/Gid, 16 from Iron on)."""
    return entity.guid.bytes.ljust(size, b"\x00")


class Participant:
    """A DDS domain participant on `domain` (see domain_id) with ROS 2 topics: `writer(name, msgtype)` and
    `reader(name, msgtype)` make endpoints on ROS 2 topic `name`. Cyclone DDS deletes them, and tells the
    peers, when the process exits. Its user data says `enclave=/;`, as rmw_cyclonedds_cpp's participants do
    (the ROS 2 graph reads the security enclave there)."""

    def __init__(self, domain: int) -> None:
        require_cyclonedds()
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.qos import Policy, Qos

        self.domain = domain
        try:
            self.participant = DomainParticipant(domain, qos=Qos(Policy.Userdata(b"enclave=/;")))
        except Exception as exc:  # a bad CYCLONEDDS_URI, no usable network interface
            raise ConfigError(f"cannot join DDS domain {domain} ({_reason(exc)}); check CYCLONEDDS_URI") from None
        self.topics: dict[str, object] = {}

    def _topic(self, name: str, msgtype: str):
        from cyclonedds.topic import Topic

        if name not in self.topics:
            self.topics[name] = Topic(self.participant, dds_topic(name), idl_class(msgtype))
        return self.topics[name]

    def writer(self, name: str, msgtype: str, depth: int = DEFAULT_DEPTH) -> CdrWriter:
        from cyclonedds.pub import DataWriter

        return CdrWriter(DataWriter(self.participant, self._topic(name, msgtype), qos=publication_qos(depth)))

    def reader(self, name: str, msgtype: str, depth: int = DEFAULT_DEPTH) -> CdrReader:
        from cyclonedds.sub import DataReader

        return CdrReader(DataReader(self.participant, self._topic(name, msgtype), qos=subscription_qos(depth)))

    def typed_writer(self, dds_name: str, cls: type, qos_):
        """A cyclonedds DataWriter of IdlStruct `cls` on DDS topic `dds_name` (as it is: no 'rt' added)."""
        from cyclonedds.pub import DataWriter

        return DataWriter(self.participant, self._dds_topic(dds_name, cls), qos=qos_)

    def typed_reader(self, dds_name: str, cls: type, qos_):
        """A cyclonedds DataReader of IdlStruct `cls` on DDS topic `dds_name` (as it is)."""
        from cyclonedds.sub import DataReader

        return DataReader(self.participant, self._dds_topic(dds_name, cls), qos=qos_)

    def _dds_topic(self, dds_name: str, cls: type):
        from cyclonedds.topic import Topic

        key = "dds:" + dds_name
        if key not in self.topics:
            self.topics[key] = Topic(self.participant, dds_name, cls)
        return self.topics[key]

    def waitset(self, readers: list):
        """A waitset woken by data on any of `readers` (CdrReaders or cyclonedds DataReaders): call .wait(ns)
        on it."""
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet

        ws = WaitSet(self.participant)
        for r in readers:
            reader = r.reader if isinstance(r, CdrReader) else r
            ws.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        return ws


class CdrWriter:
    """A DataWriter that sends CDR payloads as they are (the 4-byte encapsulation header first): cyclonedds's
    DataWriter.write takes only its own IdlStruct samples and serializes them itself; its C layer's ddspy_write,
    which write calls, takes the bytes (cyclonedds 11, pinned in pyproject.toml)."""

    def __init__(self, writer) -> None:
        self.writer = writer
        self.sent = 0

    def write(self, payload: bytes) -> None:
        from cyclonedds._clayer import ddspy_write
        from cyclonedds.core import DDSException

        data = payload + b"\x00" * (-len(payload) % _PADDING)
        ret = ddspy_write(self.writer._ref, data)
        if ret < 0:
            raise DDSException(ret, f"writing on {self.writer.topic.name}")
        self.sent += 1

    def matched(self) -> int:
        """How many subscriptions this writer is matched with."""
        return len(self.writer.get_matched_subscriptions())


class CdrReader:
    """A DataReader that gives each sample's CDR payload as it came (the encapsulation header first)."""

    def __init__(self, reader) -> None:
        self.reader = reader

    def take(self, n: int = 64) -> list[bytes]:
        """Up to `n` samples that have arrived, oldest first (disposals and unregistrations left out)."""
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import DDSException, InstanceState, SampleState, ViewState

        got = ddspy_take(self.reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, n)
        if isinstance(got, int):
            raise DDSException(got, f"taking from {self.reader.topic.name}")
        return [data for data, info in got if info.valid_data]


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
