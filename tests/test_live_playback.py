"""`datmo play`'s playback control, driven by a client written to the protocol's frames on `websockets` alone
(not datmo's code): serverInfo's capability and data range, Playback Control Requests (binary opcode 3) and the
Playback States answered (opcode 5): pause stops the messages, a seek jumps the time (forward and back), the
speed changes the rate, the end is reported and play starts over. And PlaybackControl and LogSource's start."""

from __future__ import annotations

import asyncio
import json
import math
import re
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from datmo_cli import live
from datmo_cli.live.control import ENDED, MAX_SPEED, PAUSED, PLAYING
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun

pytestmark = [pytest.mark.cli, pytest.mark.timeout(180)]

N, STEP = 100, 100_000_000  # the test log: 100 scans, 0.1 s apart (9.9 s)
T0 = 1_700_000_000_000_000_000
PLAY, PAUSE = 0, 1  # the request's command byte
STATUS = {0: PLAYING, 1: PAUSED, 2: "buffering", 3: ENDED}


def _log(path: Path) -> np.ndarray:
    """A processed log: N scans and a track message at each; returns the stamps (ns)."""
    geometry = ScanGeometry(
        angle_min=-math.pi / 2, angle_increment=math.radians(1.0), n_beams=181, range_min=0.0, range_max=8.0
    )
    stamps = T0 + np.arange(N, dtype=np.int64) * STEP
    track = np.zeros(1, cdr.element_dtype(types.TRACK))
    track["id"], track["status"] = 7, 1
    payloads = [
        cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": "laser", "tracks": track}) for s in stamps.tolist()
    ]
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("test", {})) as writer:
        writer.write_scans(ScanRun(stamps, np.full((N, 181), 5.0, np.float32), geometry))
        writer.write_many(mcapio.TOPIC_TRACKS, types.TRACKS, stamps, payloads)
    return stamps


def _request(command: int, speed: float, seek: int | None, request_id: str) -> bytes:
    """A Playback Control Request: opcode 3, command (0 play, 1 pause), speed (f32), had-seek byte, seek time
    (u64 ns), request id (u32 length, UTF-8); little-endian."""
    rid = request_id.encode()
    return struct.pack("<BBfBQI", 3, command, speed, seek is not None, seek or 0, len(rid)) + rid


def _state(frame: bytes) -> dict:
    """A Playback State: opcode 5, status, current time (u64 ns), speed (f32), did-seek byte, request id."""
    status, now, speed, sought, n = struct.unpack_from("<BQfBI", frame, 1)
    return {"status": STATUS[status], "time": now, "speed": speed, "sought": bool(sought), "id": frame[19 : 19 + n]}


class _Client:
    """What the client received, frame by frame: scans (log time of each messageData), times (opcode 2) and
    playback states (opcode 5), each with the monotonic time it arrived."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.scans: list[tuple[float, int]] = []
        self.times: list[int] = []
        self.states: list[dict] = []

    async def take(self, seconds: float) -> None:
        """Read frames for `seconds`."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                frame = await asyncio.wait_for(self.ws.recv(), left)
            except TimeoutError:
                return
            self._note(frame)

    async def until(self, done, timeout: float = 30.0) -> None:
        """Read frames until `done(self)`."""
        end = time.monotonic() + timeout
        while not done(self):
            self._note(await asyncio.wait_for(self.ws.recv(), end - time.monotonic()))

    async def ask(self, command: int, speed: float, seek: int | None, request_id: str) -> dict:
        """Send a request and read on until the state answering it: that state."""
        await self.ws.send(_request(command, speed, seek, request_id))
        await self.until(lambda c: any(s["id"] == request_id.encode() for s in c.states))
        return next(s for s in self.states if s["id"] == request_id.encode())

    def _note(self, frame) -> None:
        if isinstance(frame, bytes) and frame[0] == 1:
            self.scans.append((time.monotonic(), struct.unpack_from("<Q", frame, 5)[0]))
        elif isinstance(frame, bytes) and frame[0] == 2:
            self.times.append(struct.unpack_from("<Q", frame, 1)[0])
        elif isinstance(frame, bytes) and frame[0] == 5:
            self.states.append(_state(frame))


def _ns(t: dict) -> int:
    return t["sec"] * 1_000_000_000 + t["nsec"]


async def _session(url: str, stamps: list[int]) -> dict:
    import websockets

    out: dict = {}
    async with websockets.connect(url, subprotocols=[live.PUBLIC_SUBPROTOCOL], max_size=None) as ws:
        info = json.loads(await asyncio.wait_for(ws.recv(), 30))
        out["info"] = info
        channels: dict = {}
        while mcapio.TOPIC_SCAN not in channels:
            m = json.loads(await asyncio.wait_for(ws.recv(), 30))
            channels |= {c["topic"]: c for c in m.get("channels", [])}
        await ws.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channels[mcapio.TOPIC_SCAN]["id"]}]}
            )
        )
        c = _Client(ws)
        await c.until(lambda c: len(c.scans) >= 3)
        # requests that are not ones (too short; a command neither play nor pause): refused, playing goes on
        await ws.send(b"\x03\x01")
        await ws.send(_request(7, 1.0, None, "bad"))
        n = len(c.scans)
        await c.until(lambda c: len(c.scans) >= n + 3)
        out["bad_states"] = [s for s in c.states if s["id"] == b"bad"]

        # pause: nothing more once the answer came (what was on its way before may still land)
        out["pause"] = await c.ask(PAUSE, 1.0, None, "pause")
        await c.take(0.3)
        before = len(c.scans)
        await c.take(1.5)  # 15 scans at the log's speed
        out["paused_scans"] = len(c.scans) - before
        out["paused_at"] = c.scans[-1][1]

        # seek forward, playing: the time sought, then the scans from the first at or after it
        for name, target in (("forward", stamps[70] - STEP // 2), ("back", stamps[10])):
            n, t = len(c.scans), len(c.times)
            out[name] = await c.ask(PLAY, 1.0, target, name)
            await c.until(lambda c, n=n: len(c.scans) >= n + 3)
            out[name + "_times"] = c.times[t:]
            out[name + "_scans"] = [s for _, s in c.scans[n:]]

        # speed: 8x, then a quarter: log time over wall time of the scans that follow each
        for name, speed, count in (("fast", 8.0, 30), ("slow", 0.25, 4)):
            out[name] = await c.ask(PLAY, speed, stamps[20], name)
            n = len(c.scans)
            await c.until(lambda c, n=n, count=count: len(c.scans) >= n + count)
            (w0, s0), (w1, s1) = c.scans[n], c.scans[-1]
            out[name + "_ratio"] = (s1 - s0) / 1e9 / (w1 - w0)

        # the end: reported, and the server waits; play starts over from the first scan
        await c.ask(PLAY, 8.0, stamps[-5], "near-end")
        await c.until(lambda c: c.states[-1]["status"] == ENDED)
        out["ended"] = c.states[-1]
        await c.take(0.5)
        n = len(c.scans)
        out["again"] = await c.ask(PLAY, 8.0, None, "again")
        await c.until(lambda c, n=n: len(c.scans) >= n + 2)
        out["again_scans"] = [s for _, s in c.scans[n:]]
    return out


@pytest.mark.slow
def test_a_client_pauses_seeks_and_changes_the_speed_of_play(tmp_path):
    stamps = _log(tmp_path / "p.mcap").tolist()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from datmo_cli.cli import main; main()",
            "play",
            str(tmp_path / "p.mcap"),
            "--port",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        found = re.search(r"on (ws://\S+)$", proc.stdout.readline().strip())
        assert found, proc.stderr.read()
        out = asyncio.run(_session(found.group(1), stamps))
        # the client left: the log plays to its end (8x, the speed asked last) and play exits
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err and out["bad_states"] == []

    info = out["info"]
    assert "playbackControl" in info["capabilities"] and "time" in info["capabilities"]
    assert (_ns(info["dataStartTime"]), _ns(info["dataEndTime"])) == (stamps[0], stamps[-1])

    assert out["pause"]["status"] == PAUSED and not out["pause"]["sought"]
    assert out["paused_scans"] == 0

    forward = out["forward"]
    assert (forward["status"], forward["time"], forward["sought"]) == (PLAYING, stamps[70] - STEP // 2, True)
    assert out["forward_times"][0] == stamps[70] - STEP // 2
    assert out["forward_scans"][:3] == stamps[70:73]  # from the first scan at or after the time, in order
    assert out["back"]["time"] == stamps[10] and out["back_scans"][:3] == stamps[10:13]

    assert out["fast"]["speed"] == 8.0 and out["slow"]["speed"] == 0.25
    assert out["fast_ratio"] > 2.0  # 8x asked: well above the log's speed, however loaded the machine
    assert out["slow_ratio"] < 1.0  # a quarter asked: below the log's speed (the server never runs early)

    assert out["ended"]["status"] == ENDED and out["ended"]["time"] == stamps[-1]
    assert (out["again"]["status"], out["again"]["time"], out["again"]["sought"]) == (PLAYING, stamps[0], True)
    assert out["again_scans"][:2] == stamps[:2]


def test_playback_control_keeps_requests_within_the_log_and_its_bounds():
    c = live.PlaybackControl(100, 200, speed=2.0)
    s = c.request(True, float("nan"), None)
    assert (s.status, s.speed, s.sought) == (PLAYING, 2.0, False)  # a speed that is not one is ignored
    assert c.request(True, -1.0, None).speed == 2.0 and c.request(True, 1e9, None).speed == MAX_SPEED
    s = c.request(False, 1.0, 10)  # before the log: its start
    assert (s.status, s.time, s.sought) == (PAUSED, 100, True) and c.take_seek() == 100 and c.take_seek() is None
    assert c.request(True, 1.0, 10**12).time == 200  # after it: its end
    c.sent(200)
    assert c.finish().status == ENDED and c.request(False, 1.0, None).status == ENDED
    s = c.request(True, 1.0, None)  # play after the end: from the start
    assert (s.status, s.time, s.sought) == (PLAYING, 100, True) and c.take_seek() == 100


def test_a_log_source_starts_at_the_first_scan_at_or_after_a_time(tmp_path):
    stamps = _log(tmp_path / "p.mcap").tolist()
    source = live.LogSource(tmp_path / "p.mcap", block_scans=8)
    assert source.span == (stamps[0], stamps[-1])
    for start, first in ((stamps[0] - 5, 0), (stamps[37] - 1, 37), (stamps[37], 37), (stamps[-1], N - 1)):
        sent = [m for batch in source.batches(start) for m in batch]
        scans = [m.stamp for m in sent if m.topic == mcapio.TOPIC_SCAN]
        assert scans == stamps[first:]
        assert [m.stamp for m in sent if m.topic == mcapio.TOPIC_TRACKS] == stamps[first:]
    assert list(source.batches(stamps[-1] + 1)) == []
