"""`datmo node` in the ROS 2 graph, checked with a peer written here on cyclonedds alone: its own IDL types of
rmw_dds_common/ParticipantEntitiesInfo (Humble's 24-byte Gid), rcl_interfaces/Log and the parameter services,
written from their ROS 2 .msg/.srv definitions (not datmo's code), and rmw_cyclonedds_cpp's request header
(the client's 8-byte id and a 64-bit sequence number before each request and reply). The node runs as a
process of its own on a domain of this run's own, over the loopback interface only. Also, in process: the
parameters' names, values, refusals and the names a node may take.

No `from __future__ import annotations` here: cyclonedds reads the IDL classes' annotations as types."""

import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli.logs import mcapio

pytestmark = pytest.mark.cli

cyclonedds = pytest.importorskip("cyclonedds", reason="the node extra (cyclonedds) is not installed")

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import (  # noqa: E402
    array,
    bounded_str,
    byte,
    float64,
    int32,
    int64,
    sequence,
    uint8,
    uint32,
    uint64,
)
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.qos import Policy, Qos  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from tests.test_node import LOOPBACK, LaserScan, Tracks, _free_domain, _ns, _scan_msg, _wait_for  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HALL = ROOT / "sample_logs" / "hall.mcap"


# rmw_dds_common (ROS 2 Humble): Gid.msg, NodeEntitiesInfo.msg, ParticipantEntitiesInfo.msg


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, 24]


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: bounded_str[256]
    node_name: bounded_str[256]
    reader_gid_seq: sequence[Gid]
    writer_gid_seq: sequence[Gid]


@dataclass
class ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: Gid
    node_entities_info_seq: sequence[NodeEntitiesInfo]


# rcl_interfaces: msg/Log.msg, ParameterValue.msg, Parameter.msg, ParameterDescriptor.msg, ... and the services


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Log(IdlStruct, typename="rcl_interfaces::msg::dds_::Log_"):
    stamp: Time
    level: uint8
    name: str
    msg: str
    file: str
    function: str
    line: uint32


@dataclass
class ParameterValue(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterValue_"):
    type: uint8
    bool_value: bool
    integer_value: int64
    double_value: float64
    string_value: str
    byte_array_value: sequence[byte]
    bool_array_value: sequence[bool]
    integer_array_value: sequence[int64]
    double_array_value: sequence[float64]
    string_array_value: sequence[str]


@dataclass
class Parameter(IdlStruct, typename="rcl_interfaces::msg::dds_::Parameter_"):
    name: str
    value: ParameterValue


@dataclass
class FloatingPointRange(IdlStruct, typename="rcl_interfaces::msg::dds_::FloatingPointRange_"):
    from_value: float64
    to_value: float64
    step: float64


@dataclass
class IntegerRange(IdlStruct, typename="rcl_interfaces::msg::dds_::IntegerRange_"):
    from_value: int64
    to_value: int64
    step: uint64


@dataclass
class ParameterDescriptor(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterDescriptor_"):
    name: str
    type: uint8
    description: str
    additional_constraints: str
    read_only: bool
    dynamic_typing: bool
    floating_point_range: sequence[FloatingPointRange, 1]
    integer_range: sequence[IntegerRange, 1]


@dataclass
class SetParametersResult(IdlStruct, typename="rcl_interfaces::msg::dds_::SetParametersResult_"):
    successful: bool
    reason: str


@dataclass
class ListParametersResult(IdlStruct, typename="rcl_interfaces::msg::dds_::ListParametersResult_"):
    names: sequence[str]
    prefixes: sequence[str]


@dataclass
class ListParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Request_"):
    guid: uint64  # rmw_cyclonedds_cpp's header: the client's id ...
    seq: int64  # ... and the request's sequence number
    prefixes: sequence[str]
    depth: uint64


@dataclass
class ListParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Response_"):
    guid: uint64
    seq: int64
    result: ListParametersResult


@dataclass
class GetParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Request_"):
    guid: uint64
    seq: int64
    names: sequence[str]


@dataclass
class GetParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Response_"):
    guid: uint64
    seq: int64
    values: sequence[ParameterValue]


@dataclass
class DescribeParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Request_"):
    guid: uint64
    seq: int64
    names: sequence[str]


@dataclass
class DescribeParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Response_"):
    guid: uint64
    seq: int64
    descriptors: sequence[ParameterDescriptor]


@dataclass
class SetParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::SetParameters_Request_"):
    guid: uint64
    seq: int64
    parameters: sequence[Parameter]


@dataclass
class SetParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::SetParameters_Response_"):
    guid: uint64
    seq: int64
    results: sequence[SetParametersResult]


PARAMETER_NOT_SET, PARAMETER_INTEGER, PARAMETER_DOUBLE = 0, 2, 3
LOG_INFO, LOG_WARN = 20, 30
MOBILITY_DYNAMIC = 1  # datmo_msgs/Track


def _double(x: float) -> ParameterValue:
    return ParameterValue(PARAMETER_DOUBLE, False, 0, x, "", [], [], [], [], [])


def _integer(n: int) -> ParameterValue:
    return ParameterValue(PARAMETER_INTEGER, False, n, 0.0, "", [], [], [], [], [])


class Client:
    """A ROS 2 service client as rmw_cyclonedds_cpp makes one: requests on rq/<node>/<name>Request, replies
    on rr/<node>/<name>Reply, matched by the header."""

    def __init__(self, dp, node: str, name: str, request: type, response: type) -> None:
        qos = Qos(
            Policy.Reliability.Reliable(duration(milliseconds=100)),
            Policy.Durability.Volatile,
            Policy.History.KeepLast(10),
        )
        self.writer = DataWriter(dp, Topic(dp, f"rq{node}/{name}Request", request), qos)
        self.reader = DataReader(dp, Topic(dp, f"rr{node}/{name}Reply", response), qos)
        self.guid = int.from_bytes(self.writer.guid.bytes[8:], "little")
        self.seq = 0
        self.request = request

    def ready(self) -> bool:
        return bool(self.writer.get_matched_subscriptions() and self.reader.get_matched_publications())

    def call(self, **fields):
        self.seq += 1
        self.writer.write(self.request(guid=self.guid, seq=self.seq, **fields))
        end = time.monotonic() + 60
        while time.monotonic() < end:
            for reply in self.reader.take(10):
                if reply.guid == self.guid and reply.seq == self.seq:
                    return reply
            time.sleep(0.02)
        raise AssertionError(f"no reply to {self.request.__name__} {self.seq}")


def _endpoints(dp, builtin) -> dict[str, list[bytes]]:
    """{DDS topic: [16-byte GUIDs of its endpoints]} of what DDS discovery has seen (as ROS 2's graph reads it)."""
    out: dict[str, list[bytes]] = {}
    for sample in BuiltinDataReader(dp, builtin).read(N=1000):
        out.setdefault(sample.topic_name, []).append(sample.key.bytes)
    return out


def _service_ids(dp, builtin, kind: str) -> dict[str, set[str]]:
    """{DDS topic of `kind` ('rq' or 'rr'): the serviceid values in its endpoints' user data}: what
    rmw_cyclonedds_cpp's clients pair a service's request reader and reply writer by."""
    out: dict[str, set[str]] = {}
    for sample in BuiltinDataReader(dp, builtin).read(N=1000):
        if sample.topic_name.startswith(kind):
            user = sample.qos[Policy.Userdata]
            pairs = dict(p.split("=", 1) for p in (user.data.decode() if user else "").split(";") if "=" in p)
            name = sample.topic_name[2:].removesuffix("Request").removesuffix("Reply")
            out.setdefault(name, set()).add(pairs.get("serviceid", ""))
    return out


@pytest.mark.slow
def test_an_independent_ros2_peer_sees_datmo_in_the_graph_and_sets_a_live_parameter(tmp_path, monkeypatch):
    domain = _free_domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    monkeypatch.delenv("ROS_DISTRO", raising=False)  # Humble's Gid, as this peer's
    run = mcapio.read_run(HALL).slice(0, 160)
    node = subprocess.Popen(
        [sys.executable, "-c", "from datmo_cli.cli import main; main()", "node", "--no-config"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"PYTHONUNBUFFERED": "1"},
    )
    try:
        ready = node.stdout.readline()
        assert ready.startswith(f"datmo node: ROS 2 domain {domain}: /scan in"), (ready, node.stderr.read())
        dp = DomainParticipant(domain)
        reliable = Policy.Reliability.Reliable(duration(milliseconds=100))
        latched = Qos(reliable, Policy.Durability.TransientLocal, Policy.History.KeepLast(1000))
        discovery = DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo), latched)
        rosout = DataReader(dp, Topic(dp, "rt/rosout", Log), latched)
        scans = DataWriter(dp, Topic(dp, "rt/scan", LaserScan), Qos(reliable, Policy.History.KeepLast(10)))
        tracks = DataReader(dp, Topic(dp, "rt/datmo/tracks", Tracks), Qos(reliable, Policy.History.KeepLast(500)))
        clients = {
            name: Client(dp, "/datmo", name, *classes)
            for name, classes in {
                "list_parameters": (ListParametersRequest, ListParametersResponse),
                "get_parameters": (GetParametersRequest, GetParametersResponse),
                "describe_parameters": (DescribeParametersRequest, DescribeParametersResponse),
                "set_parameters": (SetParametersRequest, SetParametersResponse),
            }.items()
        }
        got: list[Tracks] = []
        logs: list[Log] = []
        done = threading.Event()

        def take() -> None:
            while not done.is_set():
                got.extend(tracks.take(100))
                logs.extend(rosout.take(100))
                time.sleep(0.01)

        taker = threading.Thread(target=take, daemon=True)
        taker.start()
        _wait_for(lambda: scans.get_matched_subscriptions() and tracks.get_matched_publications(), "the topics")
        _wait_for(lambda: all(c.ready() for c in clients.values()), "the parameter services")

        # the graph: /datmo with the GIDs of its endpoints, as DDS discovery knows them
        infos: list = []
        _wait_for(lambda: infos.extend(discovery.take(10)) or any(i.node_entities_info_seq for i in infos), "the node")
        (info,) = [i for i in infos if i.node_entities_info_seq]
        (entry,) = info.node_entities_info_seq
        assert (entry.node_namespace, entry.node_name) == ("/", "datmo")
        writers = {bytes(g.data) for g in entry.writer_gid_seq}
        readers = {bytes(g.data) for g in entry.reader_gid_seq}
        assert all(len(g) == 24 and not any(g[16:]) for g in writers | readers)
        publications = _endpoints(dp, BuiltinTopicDcpsPublication)
        subscriptions = _endpoints(dp, BuiltinTopicDcpsSubscription)
        for topic in ("rt/datmo/tracks", "rt/datmo/features", "rt/rosout", "rr/datmo/get_parametersReply"):
            node_side = [g for g in publications[topic] if g.ljust(24, b"\0") in writers]
            assert len(node_side) == 1, topic
            assert node_side[0][:12] == bytes(info.gid.data[:12])  # the participant's GUID prefix
        for topic in ("rt/scan", "rq/datmo/set_parametersRequest"):
            assert sum(g.ljust(24, b"\0") in readers for g in subscriptions[topic]) == 1, topic
        assert len(writers) == 6 + 2 + 4 and len(readers) == 1 + 4  # topics, rosout and events, replies
        requests = _service_ids(dp, BuiltinTopicDcpsSubscription, "rq")
        replies = _service_ids(dp, BuiltinTopicDcpsPublication, "rr")
        assert set(requests) == set(replies) == {f"/datmo/{name}" for name in clients}
        for name, ids in requests.items():
            (service_id,) = ids
            assert service_id and replies[name] == {service_id}  # the pair has one id
        assert len({next(iter(ids)) for ids in requests.values()}) == 4  # each service its own

        # the parameters, through the services
        listed = clients["list_parameters"].call(prefixes=[], depth=0).result
        assert "track.moving_speed" in listed.names and "features.d_max" in listed.names
        assert "track.d_max" not in listed.names and set(listed.prefixes) == {"features", "track"}
        values = clients["get_parameters"].call(names=["track.moving_speed", "track.tail_length", "nope"]).values
        assert [(v.type, v.double_value, v.integer_value) for v in values] == [
            (PARAMETER_DOUBLE, pytest.approx(0.2), 0),
            (PARAMETER_INTEGER, 0.0, 20),
            (PARAMETER_NOT_SET, 0.0, 0),
        ]
        live, fixed = clients["describe_parameters"].call(names=["track.moving_speed", "track.tail_length"]).descriptors
        assert not live.read_only and live.floating_point_range[0].to_value == pytest.approx(50.0)
        assert (
            fixed.read_only
            and fixed.integer_range[0].to_value == 10_000
            and "config file" in fixed.additional_constraints
        )

        def send(first: int, last: int) -> None:
            for i in range(first, last):
                scans.write(_scan_msg(int(run.stamps[i]), run.ranges[i], run.geometry))
                time.sleep(0.04)
            _wait_for(lambda: any(_ns(m.header) == run.stamps[last - 1] for m in got), "the tracks of the last scan")

        send(0, 80)
        results = (
            clients["set_parameters"]
            .call(
                parameters=[
                    Parameter("track.moving_speed", _double(50.0)),  # no track moves this fast: none is dynamic
                    Parameter("track.tail_length", _integer(5)),
                    Parameter("track.gate", _double(-1.0)),
                ]
            )
            .results
        )
        assert [r.successful for r in results] == [True, False, False]
        assert results[1].reason.startswith("track.tail_length: read when the node starts, not while it runs")
        assert results[2].reason == (
            "track.gate: must be positive, got -1; allowed: 0 < x ≤ 1000 "
            "(chi² with 2 dof; 1000 already passes anything)"
        )
        (speed,) = clients["get_parameters"].call(names=["track.moving_speed"]).values
        assert speed.double_value == pytest.approx(50.0)
        send(80, 160)
        done.set()
        taker.join()
        node.send_signal(2)
        _, err = node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
    assert node.returncode == 130, err

    def dynamic(first: int, last: int) -> int:
        stamps = set(run.stamps[first:last].tolist())
        return sum(t.mobility == MOBILITY_DYNAMIC for m in got if _ns(m.header) in stamps for t in m.tracks)

    # the effect: dynamic tracks before, none from 8 s after the change (the default keeps some; see
    # test_node_params.py: test_a_live_parameter_changes_the_running_tracker)
    assert dynamic(40, 80) > 0 and dynamic(120, 160) == 0
    lines = [(entry.level, entry.name, entry.msg) for entry in logs]
    assert lines[0][:2] == (LOG_INFO, "datmo") and lines[0][2].startswith(f"datmo node: ROS 2 domain {domain}")
    assert (LOG_INFO, "datmo", "/datmo: track.moving_speed set to 50.0") in lines
    assert any(level == LOG_WARN and "track.tail_length: read when the node starts" in text for level, _, text in lines)


# ------------------------------------------------------------------------------------------ in process


@pytest.mark.parametrize(
    "args, line",
    [
        (["--name", "2d"], "datmo: error: --name '2d': not a ROS 2 node name"),
        (["--namespace", "/a//b"], "datmo: error: --namespace '/a//b': not a ROS 2 topic name"),
        (["--ros-distro", "foxy"], "datmo: error: --ros-distro 'foxy': one of humble, iron, jazzy, kilted, rolling"),
    ],
)
def test_bad_node_names_and_distributions_are_one_line(args, line):
    from datmo_cli.cli import cli

    result = CliRunner().invoke(cli, ["node", "--no-config", "--domain-id", "3", *args])
    assert result.exit_code == 1 and result.output.splitlines() == [result.output.splitlines()[0]], result.output
    assert result.output.startswith(line), result.output


def test_names_as_rcl_makes_them():
    from datmo_cli.ros2 import ros_graph

    assert ros_graph.full_name(ros_graph.namespace("/"), "datmo") == "/datmo"
    assert ros_graph.full_name(ros_graph.namespace("robot1/front"), "tracker") == "/robot1/front/tracker"
    assert ros_graph.ros_distro("Jazzy") == "jazzy" and ros_graph.GID_SIZES["humble"] == 24
    prefix = bytes([1, 0x10, 0xAB] + [0] * 9)
    assert ros_graph.service_id(prefix, 258) == " 1.10.ab.0.0.0.0.0.0.0.0.0.0.0.1.2"  # as rmw_cyclonedds_cpp prints


def test_a_request_that_does_not_decode_is_said_once_and_skipped(monkeypatch):
    from datmo_cli.ros2 import dds, ros_graph
    from datmo_cli.ros2.node_params import Parameters

    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    graph = ros_graph.Graph(dds.Participant(_free_domain()), Parameters(), "datmo", "/", "jazzy", print)

    class Garbled:
        def take(self, n: int):
            raise ValueError("a truncated sample")

    said: list[tuple[int, str]] = []
    monkeypatch.setattr(graph, "log", lambda level, line, function="": said.append((level, line)))
    graph.services[1].request_reader = Garbled()
    assert graph.serve() == 0 and graph.serve() == 0
    assert said == [
        (LOG_WARN, "/datmo: a GetParameters request does not decode (a truncated sample); such are skipped")
    ]


def test_a_node_in_a_namespace_names_its_services_and_logger_as_rcl(monkeypatch):
    from datmo_cli.ros2 import dds, ros_graph
    from datmo_cli.ros2.node_params import Parameters

    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    ns = ros_graph.namespace("robot1")
    graph = ros_graph.Graph(dds.Participant(_free_domain()), Parameters(), "tracker", ns, "humble", print)
    assert (graph.fqn, graph.logger) == ("/robot1/tracker", "robot1.tracker")
    assert [s.request_reader.topic.name for s in graph.services] == [
        f"rq/robot1/tracker/{name}Request"
        for name in ("list_parameters", "get_parameters", "describe_parameters", "set_parameters")
    ]
    assert graph.services[3].reply_writer.topic.name == "rr/robot1/tracker/set_parametersReply"
