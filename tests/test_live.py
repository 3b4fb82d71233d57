"""The live view: `datmo play` served to a WebSocket client that subscribes and decodes the messages with an
independent decoder (mcap_ros2), transforms, pacing, record's per-scan callback, errors, and the layout."""

from __future__ import annotations

import asyncio
import json
import math
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from datmo_cli import live
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun

ROOT = Path(__file__).resolve().parents[1]
HALL = ROOT / "sample_logs" / "hall.mcap"
LAYOUT = ROOT / "foxglove-layouts" / "datmo-layout.json"
TRACK_FIELDS = {"id", "x", "y", "vx", "vy", "world_x", "world_y", "status", "mobility", "classification", "size"}

pytestmark = [pytest.mark.cli, pytest.mark.timeout(120)]


def _datmo(*args: str) -> list[str]:
    return [sys.executable, "-c", "from datmo_cli.cli import main; main()", *args]


def _decoder(channel: dict):
    schema = Schema(
        id=channel["id"],
        name=channel["schemaName"],
        encoding=channel["schemaEncoding"],
        data=channel["schema"].encode(),
    )
    return DecoderFactory().decoder_for(channel["encoding"], schema)


async def _subscribe(url: str, topics: list[str], want: int, timeout: float = 60.0) -> dict[str, list]:
    """Connect to `url`, subscribe to `topics`, and return {topic: [(frame timestamp, decoded message)]} once
    each has `want` messages."""
    import websockets

    got: dict[str, list] = {t: [] for t in topics}
    async with websockets.connect(url, subprotocols=[live.SUBPROTOCOL], max_size=None) as ws:
        channels: dict[str, dict] = {}
        while not all(t in channels for t in topics):
            m = json.loads(await asyncio.wait_for(ws.recv(), timeout))
            if m["op"] == "advertise":
                channels |= {c["topic"]: c for c in m["channels"]}
        subs = {k: channels[t] for k, t in enumerate(topics, 1)}
        await ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": k, "channelId": c["id"]} for k, c in subs.items()]})
        )
        decoders = {k: _decoder(c) for k, c in subs.items()}
        while min(len(v) for v in got.values()) < want:
            m = await asyncio.wait_for(ws.recv(), timeout)
            if isinstance(m, bytes) and m[0] == 1:  # message data: op, subscription id, timestamp, payload
                sub, stamp = struct.unpack_from("<IQ", m, 1)
                got[subs[sub]["topic"]].append((stamp, decoders[sub](m[13:])))
    return got


def _stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _serve(args: list[str]) -> tuple[subprocess.Popen, str]:
    """Start `datmo play ARGS` and return it with the ws:// URL it prints."""
    proc = subprocess.Popen(_datmo("play", *args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    found = re.search(r"on (ws://\S+)$", line.strip())
    if found is None:
        proc.kill()
        raise AssertionError(f"no URL in {line!r}: {proc.stderr.read()}")
    return proc, found.group(1)


def _play_and_stop(args: list[str], topics: list[str], want: int) -> dict[str, list]:
    """Serve with `datmo play ARGS`, receive `want` messages of each topic, then Ctrl-C: exit 130, one line."""
    proc, url = _serve(args)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert "https://app.foxglove.dev/?ds=foxglove-websocket&ds.url=" in lines[0]
        assert "Foxglove WebSocket" in lines[1] and url in lines[1]
        got = asyncio.run(_subscribe(url, topics, want))
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("datmo play: stopped (Ctrl-C)")
    return got


def test_play_serves_a_processed_log_to_a_client_that_decodes_it(tmp_path):
    run, _ = _processed_log(tmp_path / "p.mcap")
    topics = [mcapio.TOPIC_SCAN, mcapio.TOPIC_TRACKS, live.TOPIC_TF, live.TOPIC_TF_STATIC]
    got = _play_and_stop([str(tmp_path / "p.mcap"), "--port", "0", "--rate", "4", "--loop"], topics, want=2)
    stamps = run.stamps.tolist()
    for stamp, scan in got[mcapio.TOPIC_SCAN]:
        assert _stamp(scan.header) == stamp and np.array_equal(np.asarray(scan.ranges), run.ranges[0])
    for stamp, msg in got[mcapio.TOPIC_TRACKS]:
        i = stamps.index(stamp)
        (t,) = msg.tracks
        assert (t.id, t.status) == (7, 1) and math.isclose(t.x, 1.0 + 0.1 * i, rel_tol=1e-6)
    for stamp, msg in got[live.TOPIC_TF]:
        (t,) = msg.transforms
        assert (t.header.frame_id, t.child_frame_id, _stamp(t.header)) == ("odom", "base_link", stamp)
        assert math.isclose(t.transform.translation.x, 2.0 * stamps.index(stamp) / (len(stamps) - 1), abs_tol=1e-9)
    (_, static), *_ = got[live.TOPIC_TF_STATIC]
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [("base_link", "laser")]


@pytest.mark.slow
def test_play_serves_scans_and_tracks_made_on_the_fly_and_stops_on_ctrl_c():
    got = _play_and_stop(
        [str(HALL), "--port", "0", "--rate", "10", "--loop"], [mcapio.TOPIC_SCAN, mcapio.TOPIC_TRACKS], want=25
    )
    log_stamps = set(mcapio.read_messages(HALL, mcapio.TOPIC_SCAN)[0].tolist())
    scans = got[mcapio.TOPIC_SCAN]
    for stamp, scan in scans:
        assert _stamp(scan.header) == stamp and stamp in log_stamps
        assert scan.header.frame_id == "laser" and len(scan.ranges) == 361
        assert math.isclose(scan.angle_increment, math.radians(0.5), rel_tol=1e-6)
    assert [s for s, _ in scans] == sorted({s for s, _ in scans})  # in the log's order, none twice
    seen = 0
    for stamp, msg in got[mcapio.TOPIC_TRACKS]:
        assert _stamp(msg.header) == stamp and stamp in log_stamps and msg.header.frame_id == "laser"
        ids = [t.id for t in msg.tracks]
        assert len(ids) == len(set(ids))
        for t in msg.tracks:
            assert math.hypot(t.x, t.y) < 8.5 and math.isfinite(t.vx) and math.isfinite(t.vy)
            assert t.classification <= 3 and t.mobility <= 2 and t.status <= 2
        seen += len(msg.tracks)
    assert seen > 0  # the hall has people and columns


def _processed_log(path: Path, n: int = 40) -> tuple[ScanRun, list[bytes]]:
    """A small log with /scan and a hand-made /datmo/tracks (one track walking along x) and /odom."""
    geometry = ScanGeometry(
        angle_min=-math.pi / 2, angle_increment=math.radians(1.0), n_beams=181, range_min=0.0, range_max=8.0
    )
    stamps = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 100_000_000
    run = ScanRun(stamps, np.full((n, 181), 5.0, np.float32), geometry)
    track = np.zeros(1, cdr.element_dtype(types.TRACK))
    payloads = []
    for i, s in enumerate(stamps.tolist()):
        track["id"], track["x"], track["y"], track["vx"], track["status"] = 7, 1.0 + 0.1 * i, 0.5, 1.0, 1
        payloads.append(cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": "laser", "tracks": track}))
    odom = Odometry(stamps, np.linspace(0, 2, n), np.zeros(n), np.zeros(n))
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("test", {})) as writer:
        writer.write_scans(run)
        writer.write_odometry(odom)
        writer.write_many(mcapio.TOPIC_TRACKS, types.TRACKS, stamps, payloads)
    return run, payloads


def test_a_processed_log_is_served_as_it_is_with_transforms_from_its_odometry(tmp_path):
    run, payloads = _processed_log(tmp_path / "p.mcap")
    source = live.LogSource(tmp_path / "p.mcap")
    assert source.processed and not source.derived
    messages = [m for batch in source.batches() for m in batch]
    tracks = [m for m in messages if m.topic == mcapio.TOPIC_TRACKS]
    assert [m.payload for m in tracks] == payloads  # byte for byte
    assert [m.stamp for m in messages] == sorted(m.stamp for m in messages)
    at_first = [m.topic for m in messages if m.stamp == int(run.stamps[0])]
    assert at_first[0] == mcapio.TOPIC_SCAN and set(at_first) == {
        mcapio.TOPIC_SCAN,
        mcapio.TOPIC_ODOM,
        mcapio.TOPIC_TRACKS,
        live.TOPIC_TF,
        live.TOPIC_TF_STATIC,
        mcapio.TOPIC_MARKERS_TRACKS,
    }  # drawn here
    assert source.transforms.topics() == {live.TOPIC_TF: live.TF_MESSAGE, live.TOPIC_TF_STATIC: live.TF_MESSAGE}


@pytest.mark.parametrize("name", ["hall", "patrol"])
def test_a_log_stored_without_markers_gets_them_drawn_from_its_tracks_and_features(tmp_path, name):
    """datmo run stores no markers unless asked; played, its markers are drawn from its tracks and features as
    the stages draw them: the features' byte for byte, the tracks' within float32 rounding (their tails come
    from the stored positions)."""
    from datmo_cli.passes.pipeline import process_file

    src = ROOT / "sample_logs" / f"{name}.mcap"
    lean, fat = tmp_path / "lean.mcap", tmp_path / "fat.mcap"
    process_file(src, lean)
    process_file(src, fat, markers=True)
    markers = (mcapio.TOPIC_MARKERS_FEATURES, mcapio.TOPIC_MARKERS_TRACKS)
    source = live.LogSource(lean)
    assert source.processed and set(source.drawn) == set(markers)
    played: dict[str, list[live.Message]] = {}
    for m in (m for batch in source.batches() for m in batch):
        played.setdefault(m.topic, []).append(m)
    stored = {t: mcapio.read_messages(fat, t) for t in markers}
    for topic in markers:
        assert [m.stamp for m in played[topic]] == stored[topic][0].tolist(), topic
    assert [m.payload for m in played[mcapio.TOPIC_MARKERS_FEATURES]] == stored[mcapio.TOPIC_MARKERS_FEATURES][1]
    store = types.typestore()
    for m, payload in list(
        zip(played[mcapio.TOPIC_MARKERS_TRACKS], stored[mcapio.TOPIC_MARKERS_TRACKS][1], strict=True)
    )[::7]:
        a, b = (store.deserialize_cdr(p, types.MARKER_ARRAY).markers for p in (m.payload, payload))
        assert [(x.id, x.type, x.header.frame_id, len(x.points)) for x in a] == [
            (x.id, x.type, x.header.frame_id, len(x.points)) for x in b
        ]
        for x, y in zip(a, b, strict=True):
            assert np.allclose([(p.x, p.y) for p in x.points], [(p.x, p.y) for p in y.points], atol=1e-5)
    assert not live.LogSource(fat).drawn  # a log with its markers plays them as they are


def _tf_decoder():
    return _decoder(
        {
            "id": 1,
            "schemaName": live.TF_MESSAGE,
            "schemaEncoding": "ros2msg",
            "schema": types.schema_text(live.TF_MESSAGE),
            "encoding": "cdr",
        }
    )


def test_transforms_from_odometry_at_every_stamp_and_the_static_one_every_second():
    n = 30
    stamps = np.arange(n, dtype=np.int64) * 100_000_000 + 5_000_000_000
    odom = Odometry(stamps, np.linspace(0, 3, n), np.linspace(1, 2, n), np.linspace(-3.0, 3.0, n))
    messages = live.Transforms(odom, "laser", has_own=False).messages(stamps)
    decode = _tf_decoder()
    dynamic = [m for m in messages if m.topic == live.TOPIC_TF]
    static = [m for m in messages if m.topic == live.TOPIC_TF_STATIC]
    assert [m.stamp for m in dynamic] == stamps.tolist()
    assert [m.stamp for m in static] == stamps[::10].tolist()  # every second of log time
    for m, (x, y, yaw) in zip(dynamic, odom.at(stamps).tolist(), strict=True):
        (t,) = decode(m.payload).transforms
        assert (t.header.frame_id, t.child_frame_id, _stamp(t.header)) == ("odom", "base_link", m.stamp)
        assert math.isclose(t.transform.translation.x, x) and math.isclose(t.transform.translation.y, y)
        q = t.transform.rotation
        assert math.isclose(math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z), yaw, abs_tol=1e-9)
    (s,) = decode(static[0].payload).transforms
    assert (s.header.frame_id, s.child_frame_id, s.transform.rotation.w) == ("base_link", "laser", 1.0)
    assert live.Transforms(odom, "base_link", has_own=False).messages(stamps[:3])[0].topic == live.TOPIC_TF
    assert live.Transforms(odom, "laser", has_own=True).messages(stamps) == []
    assert live.Transforms(None, "laser", has_own=False).messages(stamps) == []


def test_tf_payloads_are_rosbags_bytes():
    store = types.typestore()
    cases = [[], [("odom", "base_link", 1.5, -2.25, 0.7)], [("o", "laser", 0.0, 0.0, 0.0), ("ab", "c", 3, 4, -1)]]
    for frames in cases:
        data = live.tf_payload(1_700_000_000_987_654_321, frames)
        msg = store.deserialize_cdr(data, live.TF_MESSAGE)
        assert bytes(store.serialize_cdr(msg, live.TF_MESSAGE)) == data
        assert [
            (t.header.frame_id, t.child_frame_id, t.transform.translation.x, t.transform.translation.y)
            for t in msg.transforms
        ] == [(p, c, float(x), float(y)) for p, c, x, y, _ in frames]


def test_pace_plays_at_the_rate_given():
    now = [100.0]
    pace = live.Pace(4.0, clock=lambda: now[0])
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    for stamp in (10**9, 3 * 10**9, 3 * 10**9, 11 * 10**9):
        pace.wait(stamp, sleep)
    assert slept == [0.5, 2.0]  # 2 s and 8 s of log at 4x
    now[0] += 10.0  # processing fell behind: no sleep
    pace.wait(12 * 10**9, sleep)
    assert len(slept) == 2


class _Recorder:
    """A stand-in LiveServer that keeps what is published."""

    def __init__(self) -> None:
        self.messages: list[live.Message] = []
        self.times: list[int] = []

    def publish(self, m: live.Message) -> None:
        self.messages.append(m)

    def time(self, stamp: int) -> None:
        self.times.append(stamp)


@pytest.mark.slow
def test_live_feed_publishes_each_scan_with_its_features_and_tracks():
    run = mcapio.read_run(HALL).slice(0, 60)
    server = _Recorder()
    feed = live.LiveFeed(server, batch=7)
    for i in range(len(run)):
        feed.scan(int(run.stamps[i]), run.ranges[i], run.geometry)
    feed.close(timeout=120)
    assert feed.failure is None and feed.dropped == 0 and feed.published == len(run)
    by_topic: dict[str, list[live.Message]] = {}
    for m in server.messages:
        by_topic.setdefault(m.topic, []).append(m)
    for topic in (mcapio.TOPIC_SCAN, mcapio.TOPIC_FEATURES, mcapio.TOPIC_TRACKS, mcapio.TOPIC_MARKERS_TRACKS):
        assert [m.stamp for m in by_topic[topic]] == run.stamps.tolist(), topic
    assert server.times == run.stamps.tolist()
    scan = by_topic[mcapio.TOPIC_SCAN][5].payload
    assert scan == mcapio.encode_scans(run.slice(5, 6))[0]


class _NoStages:
    """Stages that derive nothing (the view's processing is not what is tested)."""

    def __init__(self, *args, **kwargs) -> None:
        pass

    def messages(self, run: ScanRun) -> list[live.Message]:
        return []


def test_live_feed_drops_scans_rather_than_waiting(monkeypatch):
    monkeypatch.setattr(live.feed, "Stages", _NoStages)
    run = mcapio.read_run(HALL).slice(0, 11)
    gate = threading.Event()
    server = _Recorder()
    server.time = lambda stamp: gate.wait(60)  # the view is stuck on its first scan
    feed = live.LiveFeed(server, backlog=2)
    feed.scan(int(run.stamps[0]), run.ranges[0], run.geometry)
    while not feed.queue.empty():
        threading.Event().wait(0.01)
    for i in range(1, len(run)):  # the recording goes on: two wait, the others are dropped
        feed.scan(int(run.stamps[i]), run.ranges[i], run.geometry)
    assert feed.dropped == 8
    gate.set()
    feed.close(timeout=60)
    assert feed.failure is None and feed.published == 3
    sent = [m.stamp for m in server.messages if m.topic == mcapio.TOPIC_SCAN]
    assert sent == run.stamps[[0, 1, 2]].tolist()


def test_record_calls_on_scan_with_each_scan_written(tmp_path):
    from datmo_cli.lms2xx.driver import LMS2xx
    from datmo_cli.lms2xx.emulator import Emulator
    from datmo_cli.lms2xx.recorder import record
    from datmo_cli.passes.simulated import SceneSource

    seen: list[tuple[int, np.ndarray, ScanGeometry]] = []
    with Emulator(SceneSource("hall", seed=3, duration=10)) as emu:
        driver = LMS2xx(emu.device_path, baud=500000)
        writer = mcapio.LogWriter(tmp_path / "r.mcap", provenance=mcapio.Provenance("record", {}), streaming=True)
        record(driver, writer, max_scans=8, on_scan=lambda stamp, ranges, g: seen.append((stamp, np.array(ranges), g)))
    run = mcapio.read_run(tmp_path / "r.mcap")
    assert [s for s, _, _ in seen] == run.stamps.tolist()
    assert np.array_equal(np.stack([r for _, r, _ in seen]), run.ranges)
    assert all(g.same_beams(run.geometry) for _, _, g in seen)


def test_a_busy_port_is_one_line_naming_the_option():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = CliRunner().invoke(cli, ["play", str(HALL), "--port", str(port)])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"datmo: error: --port {port}: cannot serve on 127.0.0.1:{port} (")


@pytest.mark.parametrize(
    "args, name",
    [
        (["--port", "70000"], "--port"),
        (["--port", "-1"], "--port"),
        (["--rate", "0"], "--rate"),
        (["--rate", "nan"], "--rate"),
    ],
)
def test_bad_port_or_rate_is_one_line(args, name):
    result = CliRunner().invoke(cli, ["play", str(HALL), *args])
    assert result.exit_code == 2 and result.output.startswith(f"datmo: error: {name}: "), result.output


def test_urls():
    assert live.ws_url("127.0.0.1", 8765) == "ws://127.0.0.1:8765"
    assert live.ws_url("::1", 9) == "ws://[::1]:9"
    assert live.ws_url("0.0.0.0", 1) == f"ws://{socket.gethostname()}:1"
    assert live.app_url("127.0.0.1", 8765) == (
        "https://app.foxglove.dev/?ds=foxglove-websocket&ds.url=ws%3A%2F%2F127.0.0.1%3A8765"
    )


def _tree_leaves(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _tree_leaves(node["first"]) + _tree_leaves(node["second"])


def test_the_foxglove_layout_shows_scan_features_tracks_and_a_plot_of_track_velocities():
    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    assert set(layout) >= {"configById", "layout", "globalVariables", "userNodes"}
    panels = layout["configById"]
    assert sorted(_tree_leaves(layout["layout"])) == sorted(panels)  # every panel placed, none missing
    (three_d,) = [v for k, v in panels.items() if k.startswith("3D!")]
    assert three_d["followTf"] == "laser"  # the scan's frame; odom is the root
    for topic in (mcapio.TOPIC_SCAN, mcapio.TOPIC_MARKERS_FEATURES, mcapio.TOPIC_MARKERS_TRACKS):
        assert three_d["topics"][topic]["visible"] is True
    (plot,) = [v for k, v in panels.items() if k.startswith("Plot!")]
    paths = [p["value"] for p in plot["paths"]]
    assert paths and all(p.startswith(mcapio.TOPIC_TRACKS + ".tracks[:]") for p in paths)
    track_fields = {
        line.split()[1]
        for line in types.datmo_msg_files()[types.TRACK].splitlines()
        if line and not line.startswith("#") and "=" not in line
    }
    for p in paths:
        fields = re.findall(r"\{(\w+)==\d+\}|\.(\w+)$", p)
        assert {f for pair in fields for f in pair if f} <= track_fields, p
    assert {"vx", "vy"} <= {p.rsplit(".", 1)[1] for p in paths} and TRACK_FIELDS <= track_fields


# -------------------------------------------------------------------------------------- play --loop


class _Passes(_Recorder):
    """A stand-in LiveServer for play(): counts the passes (restarts) and stops play after `passes`."""

    def __init__(self, passes: int) -> None:
        super().__init__()
        self.passes, self.restarts = passes, 0

    def repeat_static(self, stamp: int) -> None:
        pass

    def restart(self) -> None:
        self.restarts += 1
        if self.restarts == self.passes:
            raise KeyboardInterrupt


def test_play_loop_of_a_one_scan_log_waits_between_passes(tmp_path):
    _processed_log(tmp_path / "one.mcap", n=1)
    source = live.LogSource(tmp_path / "one.mcap")
    now = [0.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    server = _Passes(passes=5)
    with pytest.raises(KeyboardInterrupt):
        live.play(source, server, rate=1000.0, loop=True, sleep=sleep, clock=lambda: now[0])
    assert [m.topic for m in server.messages].count(mcapio.TOPIC_SCAN) == 5
    # the clock moves only when play sleeps: each pass of a one-scan log is padded to the minimum period
    assert slept == [live.MIN_LOOP_PASS_S] * 5


# ------------------------------------------------------ clients of either subprotocol, and leaving quietly


async def _spec_client(url: str, subprotocol: str, topics: list[str], want: int, timeout: float = 60.0) -> dict:
    """A client written to the public protocol (github.com/foxglove/ws-protocol, on websockets alone): asks for
    `subprotocol`, reads serverInfo and the advertised channels, subscribes to `topics`, takes `want` messages
    of each (messageData: opcode 1, subscription id, timestamp, payload) and the time frames (opcode 2) that
    come meanwhile, unsubscribes and leaves."""
    import websockets

    out: dict = {"messages": {t: [] for t in topics}, "times": [], "channels": {}}
    async with websockets.connect(url, subprotocols=[subprotocol], max_size=None) as ws:
        out["subprotocol"] = ws.subprotocol
        out["server_info"] = json.loads(await asyncio.wait_for(ws.recv(), timeout))
        while not all(t in out["channels"] for t in topics):
            m = json.loads(await asyncio.wait_for(ws.recv(), timeout))
            if m["op"] == "advertise":
                out["channels"] |= {c["topic"]: c for c in m["channels"]}
        subs = {k: out["channels"][t]["id"] for k, t in enumerate(topics, 1)}
        await ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": k, "channelId": c} for k, c in subs.items()]})
        )
        got = out["messages"]
        while min(len(v) for v in got.values()) < want:
            m = await asyncio.wait_for(ws.recv(), timeout)
            if isinstance(m, bytes) and m[0] == 1:
                sub, stamp = struct.unpack_from("<IQ", m, 1)
                got[topics[sub - 1]].append((stamp, m[13:]))
            elif isinstance(m, bytes) and m[0] == 2:
                out["times"].append(struct.unpack_from("<Q", m, 1)[0])
        await ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": list(subs)}))
    return out


async def _vanish(url: str) -> None:
    """A client that subscribes to everything, takes one message and drops the connection (no close frame)."""
    import websockets

    async with websockets.connect(url, subprotocols=[live.PUBLIC_SUBPROTOCOL], max_size=None) as ws:
        channels = []
        while not channels:
            m = json.loads(await asyncio.wait_for(ws.recv(), 60))
            channels = [c["id"] for c in m.get("channels", [])]
        await ws.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": i, "channelId": c} for i, c in enumerate(channels)]}
            )
        )
        while not isinstance(await asyncio.wait_for(ws.recv(), 60), bytes):
            pass
        ws.transport.abort()


def test_play_serves_clients_of_either_subprotocol_and_says_nothing_when_they_leave(tmp_path):
    run, payloads = _processed_log(tmp_path / "p.mcap")
    by_stamp = dict(zip(run.stamps.tolist(), payloads, strict=True))
    proc, url = _serve([str(tmp_path / "p.mcap"), "--port", "0", "--rate", "8", "--loop"])
    try:
        for subprotocol in (live.PUBLIC_SUBPROTOCOL, live.SUBPROTOCOL):
            got = asyncio.run(_spec_client(url, subprotocol, [mcapio.TOPIC_TRACKS, mcapio.TOPIC_SCAN], want=3))
            assert got["subprotocol"] == subprotocol
            info = got["server_info"]
            assert info["op"] == "serverInfo" and info["name"] == "datmo" and "time" in info["capabilities"]
            tracks = got["channels"][mcapio.TOPIC_TRACKS]
            assert (tracks["encoding"], tracks["schemaName"], tracks["schemaEncoding"]) == (
                "cdr",
                types.TRACKS,
                "ros2msg",
            )
            for stamp, payload in got["messages"][mcapio.TOPIC_TRACKS]:
                assert payload == by_stamp[stamp]  # the log's bytes, at the log's time
            for stamp, payload in got["messages"][mcapio.TOPIC_SCAN]:
                assert stamp in by_stamp and payload[:4] == cdr.CDR_HEADER
            assert got["times"] and set(got["times"]) <= set(by_stamp)
        import websockets

        asyncio.run(_vanish(url))
        with pytest.raises(websockets.InvalidStatus, match="400"):  # as foxglove-sdk's server answers
            asyncio.run(_spec_client(url, "some.other.v1", [mcapio.TOPIC_SCAN], want=1))
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130
    # two clients left (and one was turned away): nothing on stderr but play's own two lines
    lines = err.splitlines()
    assert lines[0] == "  waiting for a client to subscribe (Ctrl-C to stop)" and len(lines) == 2, err
    assert re.fullmatch(r"datmo play: stopped \(Ctrl-C\); [\d,]+ messages served", lines[1]), err


def test_play_help_says_what_the_viewer_can_and_cannot_do():
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    text = " ".join(CliRunner().invoke(cli, ["play", "--help"]).output.split())
    assert "What the viewer can do" in text and "pause and play, seek to a time in the log" in text
    assert "change the speed (--rate is the speed to start at)" in text
    assert "What it cannot do: step a scan at a time, or play backwards" in text
