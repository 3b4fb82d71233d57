"""`datmo node` in the ROS 2 graph, over DDS with no ROS installation, as rmw_cyclonedds_cpp and rcl put it on
the wire: the node announced on `ros_discovery_info`, its log lines on `/rosout`, its parameters served.

- `ros_discovery_info` (DDS topic of that name, type rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_,
  reliable, transient-local, keep last 1): the participant's GID and one node, its name and namespace with the
  GIDs of its readers and writers. A GID is the entity's 16-byte DDS GUID, padded with zeros to the size of
  rmw_dds_common/Gid: 24 bytes in Humble, 16 from Iron on (`ros_distro`). ROS 2's graph pairs these GIDs with
  the endpoints DDS discovers, which is how `ros2 node list` and `ros2 topic info -v` name the node.
- `/rosout` (rcl_interfaces/msg/Log; reliable, transient-local, keep last 1000, lifespan 10 s as rcl's
  rosout profile): the node's own lines, its logger named as rcl names it (`datmo`, `ns.datmo`).
- `/parameter_events` (rcl_interfaces/msg/ParameterEvent; reliable, volatile, keep last 1000): the parameters
  at start (new) and each accepted change.
- The services `~/list_parameters`, `~/get_parameters`, `~/describe_parameters`, `~/set_parameters`: the DDS
  topics `rq/<node>/<service>Request` and `rr/<node>/<service>Reply` of types
  `rcl_interfaces::srv::dds_::<Service>_Request_` / `_Response_` (reliable, volatile, keep last 10). As in
  rmw_cyclonedds_cpp, each request starts with a header (the client's 8-byte id, then a 64-bit sequence
  number) that the reply repeats, so the client knows its answer.
Stamps: the machine's clock (ROS time without /clock), ns.
"""

from __future__ import annotations

import os
import re
import time
import types as pytypes
from dataclasses import dataclass
from functools import cache
from typing import Any

from ..base.errors import ConfigError
from . import dds
from .node_params import BOOL, DOUBLE, INTEGER, NOT_SET, STRING, Parameters

GID_SIZES = {"humble": 24, "iron": 16, "jazzy": 16, "kilted": 16, "rolling": 16}  # rmw_dds_common/Gid
DISCOVERY_TOPIC = "ros_discovery_info"
ROSOUT = "/rosout"
PARAMETER_EVENTS = "/parameter_events"
SERVICES = {
    "list_parameters": "ListParameters",
    "get_parameters": "GetParameters",
    "describe_parameters": "DescribeParameters",
    "set_parameters": "SetParameters",
}
DEBUG, INFO, WARN, ERROR = 10, 20, 30, 40  # rcl_interfaces/msg/Log levels
_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def ros_distro(value: str | None) -> str:
    """The ROS 2 distribution whose rmw_dds_common to speak: `value`, else ROS_DISTRO, else humble;
    ConfigError for one not known."""
    source = "--ros-distro" if value else "ROS_DISTRO"
    name = (value or os.environ.get("ROS_DISTRO", "") or "humble").strip().lower()
    if name not in GID_SIZES:
        raise ConfigError(f"{source} {name!r}: one of {', '.join(GID_SIZES)}")
    return name


def node_name(name: str) -> str:
    """`name` when ROS 2 takes it as a node name (letters, digits, underscores, not starting with a digit)."""
    if not _NODE_NAME.fullmatch(name):
        raise ConfigError(
            f"--name {name!r}: not a ROS 2 node name (letters, digits and underscores, not starting with a digit)"
        )
    return name


def namespace(ns: str) -> str:
    """The absolute namespace of `ns` ('/' for the root, else '/a/b')."""
    return "/" if ns.strip() in ("", "/") else dds.ros_topic(ns, "--namespace")


def full_name(ns: str, name: str) -> str:
    """The node's fully qualified name: '/datmo', '/robot1/datmo'."""
    return f"{ns.rstrip('/')}/{name}"


# ------------------------------------------------------------------------------------------ IDL types


def _struct(typename: str, annotations: dict) -> type:
    from dataclasses import dataclass as _dataclass

    from cyclonedds.idl import IdlStruct

    def body(namespace_: dict) -> None:
        namespace_["__annotations__"] = annotations
        namespace_["__module__"] = __name__

    name = typename.replace("::", "_")
    return _dataclass(pytypes.new_class(name, (IdlStruct,), {"typename": typename}, body))


@cache
def discovery_classes(gid_size: int) -> tuple[type, type, type]:
    """rmw_dds_common/msg/ Gid (of `gid_size` bytes), NodeEntitiesInfo and ParticipantEntitiesInfo."""
    from cyclonedds.idl import types as t

    arr: Any = t.array
    bstr: Any = t.bounded_str
    seq: Any = t.sequence

    gid = _struct("rmw_dds_common::msg::dds_::Gid_", {"data": arr[t.uint8, gid_size]})
    node = _struct(
        "rmw_dds_common::msg::dds_::NodeEntitiesInfo_",
        {
            "node_namespace": bstr[256],
            "node_name": bstr[256],
            "reader_gid_seq": seq[gid],
            "writer_gid_seq": seq[gid],
        },
    )
    info = _struct(
        "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_", {"gid": gid, "node_entities_info_seq": seq[node]}
    )
    return gid, node, info


def msg(name: str) -> type:
    """The IdlStruct of rcl_interfaces/msg/`name` (ROS 2 Humble's definition, the same through Jazzy)."""
    return dds.idl_class(f"rcl_interfaces/msg/{name}")


@cache
def service_classes(service: str) -> tuple[type, type]:
    """(request, reply) IdlStructs of rcl_interfaces/srv/`service`, each after rmw_cyclonedds_cpp's header."""
    from cyclonedds.idl import types as t

    seq: Any = t.sequence  # a type built at run time (mypy takes t.sequence[...] for a type expression)

    fields = {
        "ListParameters": ({"prefixes": seq[str], "depth": t.uint64}, {"result": msg("ListParametersResult")}),
        "GetParameters": ({"names": seq[str]}, {"values": seq[msg("ParameterValue")]}),
        "DescribeParameters": ({"names": seq[str]}, {"descriptors": seq[msg("ParameterDescriptor")]}),
        "SetParameters": (
            {"parameters": seq[msg("Parameter")]},
            {"results": seq[msg("SetParametersResult")]},
        ),
    }[service]
    header = {"guid": t.uint64, "seq": t.int64}  # rmw_cyclonedds_cpp's cdds_request_header_t
    request, response = fields
    return (
        _struct(f"rcl_interfaces::srv::dds_::{service}_Request_", header | request),
        _struct(f"rcl_interfaces::srv::dds_::{service}_Response_", header | response),
    )


# ------------------------------------------------------------------------------------------ values


def to_value(value: object):
    """rcl_interfaces/msg/ParameterValue of a Python value (None: NOT_SET)."""
    kind = (
        NOT_SET
        if value is None
        else BOOL
        if isinstance(value, bool)
        else INTEGER
        if isinstance(value, int)
        else DOUBLE
        if isinstance(value, float)
        else STRING
    )
    return msg("ParameterValue")(
        type=kind,
        bool_value=bool(value) if kind == BOOL else False,
        integer_value=int(value) if kind == INTEGER else 0,  # type: ignore[call-overload]
        double_value=float(value) if kind == DOUBLE else 0.0,  # type: ignore[arg-type]
        string_value=str(value) if kind == STRING else "",
        byte_array_value=[],
        bool_array_value=[],
        integer_array_value=[],
        double_array_value=[],
        string_array_value=[],
    )


def from_value(v) -> object:
    """The Python value of a ParameterValue (arrays as lists; NOT_SET: None)."""
    names = {
        BOOL: "bool_value",
        INTEGER: "integer_value",
        DOUBLE: "double_value",
        STRING: "string_value",
        5: "byte_array_value",
        6: "bool_array_value",
        7: "integer_array_value",
        8: "double_array_value",
        9: "string_array_value",
    }
    return getattr(v, names[v.type]) if v.type in names else None


def service_id(prefix: bytes, k: int) -> str:
    """The id rmw_cyclonedds_cpp puts in a service's reader and writer user data (`serviceid=ID;`), which its
    clients use to pair a request reader with a reply writer: the participant's 12-byte GUID prefix and the
    big-endian count `k`, in hex, the bytes separated by dots."""
    data = prefix + k.to_bytes(4, "big")
    return f"{data[0]:2x}" + "".join(f".{b:x}" for b in data[1:])


def _time(ns: int):
    return dds.idl_class("builtin_interfaces/msg/Time")(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


# ------------------------------------------------------------------------------------------ the node


@dataclass
class Service:
    name: str
    request_reader: object
    reply_writer: object


class Graph:
    """The node `name` in namespace `ns` on `participant`: its services, /rosout and /parameter_events
    endpoints made now; `announce(readers, writers)` publishes it on ros_discovery_info with the GIDs of its
    other endpoints (DataReaders and DataWriters); `serve()` answers the requests that arrived; `log(level,
    line)` writes to /rosout. `on_change(config)` is called with the configuration after each accepted change."""

    def __init__(
        self, participant: dds.Participant, params: Parameters, name: str, ns: str, distro: str, on_change
    ) -> None:
        self.participant, self.params, self.on_change = participant, params, on_change
        self.name, self.ns = name, ns
        self.fqn = full_name(ns, name)
        self.logger = ".".join([*ns.strip("/").split("/"), name]) if ns != "/" else name
        self.gid_size = GID_SIZES[distro]
        p = participant
        self.rosout = p.typed_writer(
            dds.dds_topic(ROSOUT), msg("Log"), dds.qos(transient_local=True, depth=1000, lifespan_s=10)
        )
        self.events = p.typed_writer(dds.dds_topic(PARAMETER_EVENTS), msg("ParameterEvent"), dds.qos(depth=1000))
        self.services = []
        prefix = participant.participant.guid.bytes[:12]
        for k, (short, service) in enumerate(SERVICES.items(), start=1):
            request, reply = service_classes(service)
            base = f"{self.fqn}/{short}"
            paired = dds.qos(userdata=f"serviceid={service_id(prefix, k)};".encode())
            self.services.append(
                Service(
                    service,
                    p.typed_reader(f"rq{base}Request", request, paired),
                    p.typed_writer(f"rr{base}Reply", reply, paired),
                )
            )
        self.discovery = p.typed_writer(
            DISCOVERY_TOPIC, discovery_classes(self.gid_size)[2], dds.qos(transient_local=True, depth=1)
        )
        self.served = 0
        self.bad: set[str] = set()

    def readers(self) -> list:
        """The service request readers (for the node's waitset)."""
        return [s.request_reader for s in self.services]

    def announce(self, readers: list, writers: list) -> None:
        """Publish the participant's entities: this node with `readers` and `writers` (DataReaders and
        DataWriters), its services' and log's endpoints; then the parameters as new on /parameter_events."""
        gid_t, node_t, info = discovery_classes(self.gid_size)

        def gids(entities: list) -> list:
            return [gid_t(data=list(dds.gid(e, self.gid_size))) for e in entities]

        node = node_t(
            node_namespace=self.ns,
            node_name=self.name,
            reader_gid_seq=gids(readers + self.readers()),
            writer_gid_seq=gids([*writers, self.rosout, self.events, *(s.reply_writer for s in self.services)]),
        )
        self.discovery.write(
            info(
                gid=gid_t(data=list(dds.gid(self.participant.participant, self.gid_size))),
                node_entities_info_seq=[node],
            )
        )
        self._event(new=self.params.names())

    def log(self, level: int, line: str, function: str = "") -> None:
        """One line on /rosout at `level` (INFO, WARN, ...), stamped now."""
        self.rosout.write(
            msg("Log")(
                stamp=_time(time.time_ns()),
                level=level,
                name=self.logger,
                msg=line,
                file="datmo_cli/ros2/node.py",
                function=function,
                line=0,
            )
        )

    def serve(self) -> int:
        """Answer every request that arrived; returns how many. A request that does not decode is skipped
        and said on /rosout (the first of each service)."""
        n = 0
        for s in self.services:
            try:
                requests = s.request_reader.take(64)  # type: ignore[attr-defined]
            except Exception as exc:  # cyclonedds raises several kinds for a sample that does not decode
                if s.name not in self.bad:
                    self.bad.add(s.name)
                    self.log(WARN, f"{self.fqn}: a {s.name} request does not decode ({exc}); such are skipped")
                continue
            for request in requests:
                reply = getattr(self, "_" + s.name)(request)
                s.reply_writer.write(  # type: ignore[attr-defined]
                    service_classes(s.name)[1](guid=request.guid, seq=request.seq, **reply)
                )
                n += 1
        self.served += n
        return n

    def _ListParameters(self, request) -> dict:
        names, prefixes = self.params.list(list(request.prefixes), int(request.depth))
        return {"result": msg("ListParametersResult")(names=names, prefixes=prefixes)}

    def _GetParameters(self, request) -> dict:
        return {"values": [to_value(self.params.get(n)) for n in request.names]}

    def _DescribeParameters(self, request) -> dict:
        out = []
        for name in request.names:
            d = self.params.describe(name)
            fp, ir = [], []
            if d is not None and d.bound is not None:
                lo, hi = d.bound.lo, d.bound.hi
                if d.type == INTEGER:
                    ir = [msg("IntegerRange")(from_value=int(lo), to_value=int(hi), step=0)]
                else:
                    fp = [msg("FloatingPointRange")(from_value=float(lo), to_value=float(hi), step=0.0)]
            out.append(
                msg("ParameterDescriptor")(
                    name=name,
                    type=NOT_SET if d is None else d.type,
                    description="" if d is None else d.description,
                    additional_constraints="not a parameter of datmo" if d is None else d.constraints,
                    read_only=d is not None and d.read_only,
                    dynamic_typing=False,
                    floating_point_range=fp,
                    integer_range=ir,
                )
            )
        return {"descriptors": out}

    def _SetParameters(self, request) -> dict:
        results, changed = [], []
        for p in request.parameters:
            value = from_value(p.value)
            reason = self.params.set(p.name, value)
            results.append(msg("SetParametersResult")(successful=not reason, reason=reason))
            if reason:
                self.log(WARN, f"{self.fqn}: set_parameters: {reason}", "set_parameters")
            else:
                changed.append(p.name)
                self.log(INFO, f"{self.fqn}: {p.name} set to {self.params.get(p.name)!r}", "set_parameters")
        if changed:
            self.on_change(self.params.config)
            self._event(changed=changed)
        return {"results": results}

    def _event(self, new: list[str] = (), changed: list[str] = ()) -> None:  # type: ignore[assignment]
        def params(names):
            return [msg("Parameter")(name=n, value=to_value(self.params.get(n))) for n in names]

        self.events.write(
            msg("ParameterEvent")(
                stamp=_time(time.time_ns()),
                node=self.fqn,
                new_parameters=params(new),
                changed_parameters=params(changed),
                deleted_parameters=[],
            )
        )
