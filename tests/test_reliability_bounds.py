"""Reads bounded everywhere, round 3: a zstd frame stating more than its chunk declares, a ROS 1 bag's bz2 and
lz4 chunks, a bag folder's metadata.yaml and members that are devices, FIFOs or too large, a leg model of
100,000 tiny members, a play client's oversized frame. Memory is measured as the peak RSS of a subprocess
against a generous bound, never by timing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import pytest
from test_reliability_bombs import mcap_with_chunk, messages

pytestmark = [pytest.mark.unit, pytest.mark.timeout(180)]

RSS_BOUND_MB = 400  # generous: the bombs below take over 1,000 MB when unbounded


SPACE_LIMIT = 2 << 30  # address space of a measured process: an unbounded read fails there, never the machine


def run_measured(code: str, tmp_path: Path, timeout: float = 170) -> dict:
    """Run `code` (which sets `out`, a dict) in a fresh interpreter of at most SPACE_LIMIT bytes of address
    space; `out` with the peak RSS in MB as "rss_mb". The process failing (out of memory) or running past
    `timeout` (blocked) fails the test."""
    script = "import resource\n" + f"resource.setrlimit(resource.RLIMIT_AS, ({SPACE_LIMIT}, {SPACE_LIMIT}))\n"
    script += textwrap.dedent(code) + textwrap.dedent(
        """
        import json
        # VmHWM, this program's own peak: ru_maxrss keeps the forking process's peak across exec on Linux (an
        # xdist worker's, 950 MB)
        with open("/proc/self/status") as status:
            hwm = next(line for line in status if line.startswith("VmHWM:"))
        out["rss_mb"] = int(hwm.split()[1]) / 1024
        print(json.dumps(out))
        """
    )
    try:
        proc = subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=timeout, check=False
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running after {timeout} s (blocked)")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def zstd_stating(size: int, data: bytes = b"") -> bytes:
    """A zstd frame that states `size` bytes of content in its header: `data` then zeros."""
    import zstandard

    c = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    parts = [c.compress(data)]
    zeros = bytes(1 << 20)
    left = size - len(data)
    while left > 0:
        parts.append(c.compress(zeros[: min(left, len(zeros))]))
        left -= len(zeros)
    parts.append(c.flush())
    return b"".join(parts)


def test_a_zstd_frame_stating_1_gib_in_a_chunk_declaring_1_mib_is_skipped_in_bounded_memory(tmp_path):
    _, payloads = mcap_with_chunk("", b"", 0)
    inner = messages(payloads)
    data, _ = mcap_with_chunk("zstd", zstd_stating(1 << 30, inner), 1 << 20)
    (tmp_path / "bomb.mcap").write_bytes(data)
    out = run_measured(
        """
        import warnings
        from datmo_cli.logs import mcapio
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            log = mcapio.read_log("bomb.mcap", topics=None)
        out = {"corrupt": log.corrupt_chunks, "warnings": [str(w.message) for w in seen]}
        """,
        tmp_path,
    )
    assert out["corrupt"] == 1, out
    assert any("decompresses to more than the 1,048,576 bytes its header says" in w for w in out["warnings"]), out
    assert out["rss_mb"] < RSS_BOUND_MB, out


def test_a_sound_zstd_chunk_stating_its_size_still_reads(tmp_path):
    from datmo_cli.logs import mcapio

    _, payloads = mcap_with_chunk("", b"", 0)
    inner = messages(payloads)
    data, _ = mcap_with_chunk("zstd", zstd_stating(len(inner), inner), len(inner))
    (tmp_path / "sound.mcap").write_bytes(data)
    assert len(mcapio.read_run(tmp_path / "sound.mcap")) == 3


def ros1_bag_with_chunk(path: Path, compression: str, bomb: bytes | None) -> Path:
    """A ROS 1 bag of five scans and poses in `compression` chunks; with `bomb`, each chunk's data is replaced
    by it (its header still declares the real, small, size)."""
    from rosbags.rosbag1 import Writer
    from test_import_rosbag import STORE1, messages

    w = Writer(path)
    w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    if bomb is not None:
        w.compressor = lambda data: bomb
    with w:
        conns = {}
        for topic, msgtype, t, make in messages():
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE1)
            w.write(conns[topic], t, STORE1.serialize_ros1(make(STORE1), msgtype))
    return path


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_ros1_bag_chunk_decompressing_to_1_gib_is_refused_in_bounded_memory(tmp_path, compression):
    import bz2

    import lz4.frame

    if compression == "bz2":
        bomb = bz2.compress(bytes(64 << 20), 1) * 16  # 1 GiB of zeros in 16 streams of 447 bytes
    else:
        bomb = lz4.frame.compress(bytes(1 << 30))
    ros1_bag_with_chunk(tmp_path / "bomb.bag", compression, bomb)
    out = run_measured(
        """
        from datmo_cli.base.errors import InputError
        from datmo_cli.logs.importers import import_log
        try:
            import_log("bomb.bag", topic="/front")
            out = {"error": None}
        except InputError as exc:
            out = {"error": str(exc)}
        """,
        tmp_path,
    )
    assert out["error"] and out["error"].startswith("bomb.bag: cannot read bag"), out
    assert "decompresses to more than the" in out["error"], out
    assert out["rss_mb"] < RSS_BOUND_MB, out


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_sound_compressed_ros1_bag_reads_whole(tmp_path, compression):
    from datmo_cli.logs.importers import import_log

    res = import_log(ros1_bag_with_chunk(tmp_path / "sound.bag", compression, None), topic="/front")
    assert len(res.run) == 5 and res.odometry is not None and len(res.odometry) == 5


IMPORT_BAG = """
from datmo_cli.base.errors import InputError
from datmo_cli.logs.importers import import_log
try:
    import_log("BAG")
    out = {"error": None}
except InputError as exc:
    out = {"error": str(exc)}
"""


@pytest.fixture
def ros2_bag(tmp_path):
    from test_import_rosbag import messages, write_ros2

    return write_ros2(tmp_path / "b2", messages(), topics={"/front"})


def _swap(path: Path, kind: str) -> None:
    path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    else:  # a sparse regular file larger than the cap
        with open(path, "wb") as f:
            f.truncate((16 << 20) + 1)


@pytest.mark.parametrize(
    ("which", "kind"),
    # a member is a log, whatever its size: its reads are bounded chunk by chunk
    [
        ("metadata.yaml", "fifo"),
        ("metadata.yaml", "zero"),
        ("metadata.yaml", "large"),
        ("member", "fifo"),
        ("member", "zero"),
    ],
)
def test_a_bag_folder_file_that_is_not_a_sane_regular_file_is_refused_naming_it(ros2_bag, which, kind):
    path = ros2_bag / "metadata.yaml" if which == "metadata.yaml" else next(ros2_bag.glob("*.mcap"))
    _swap(path, kind)
    out = run_measured(IMPORT_BAG.replace("BAG", str(ros2_bag)), ros2_bag.parent, timeout=30)
    text = out["error"]
    assert text and text.startswith(f"{path}: "), out
    expected = {"fifo": "is a FIFO", "zero": "is a character device", "large": "is at most 16,777,216 bytes"}[kind]
    assert expected in text, text


def test_a_sound_bag_folder_still_reads(ros2_bag):
    from datmo_cli.logs.importers import import_log

    assert len(import_log(ros2_bag).run) == 5


def test_a_bag_folder_member_whose_zstd_frame_states_1_gib_is_refused_in_bounded_memory(tmp_path, monkeypatch):
    """A ROS 2 bag folder whose MCAP member's first chunk holds a zstd frame stating 1 GiB (its header declares
    the real size): rosbags' reader decompressed it whole."""
    import synthetic_logs

    from datmo_cli.logs import bagdir, mcap_chunks

    class Bomb:
        def __init__(self, real):
            self.real, self.first = real, True

        def compress(self, data):
            if self.first:
                self.first = False
                return zstd_stating(1 << 30, data)
            return self.real.compress(data)

    made = mcap_chunks.ChunkWriter.__init__

    def init(self, *args, **kwargs):
        made(self, *args, **kwargs)
        self._zstd = Bomb(self._zstd)
        if hasattr(self, "_zstd_small"):  # the compressor of small chunks
            self._zstd_small = Bomb(self._zstd_small)

    monkeypatch.setattr(mcap_chunks.ChunkWriter, "__init__", init)
    with warnings.catch_warnings(), bagdir.writing(tmp_path / "bag") as log_file:
        warnings.simplefilter("ignore")  # metadata.yaml's summary, read by datmo's reader, skips the bomb
        synthetic_logs.write(log_file)
    monkeypatch.undo()
    out = run_measured(
        """
        from datmo_cli.base.errors import InputError
        from datmo_cli.logs.importers import import_log
        try:
            import_log("bag")
            out = {"error": None}
        except InputError as exc:
            out = {"error": str(exc)}
        """,
        tmp_path,
    )
    assert out["error"] and out["error"].startswith("bag: cannot read bag"), out
    assert "decompresses to more than the" in out["error"], out
    assert out["rss_mb"] < RSS_BOUND_MB, out


def test_a_leg_model_of_100000_tiny_members_is_refused_before_any_is_opened(tmp_path, monkeypatch):
    import zipfile

    import numpy as np

    from datmo_cli.base.errors import InputError
    from datmo_cli.perception import leg_model

    path = tmp_path / "many.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
        for i in range(100_000):
            zf.writestr(f"m{i}.npy", b"")

    def opened(*args, **kwargs):
        raise AssertionError("a member was opened")

    monkeypatch.setattr(np.lib.format, "read_magic", opened)
    with pytest.raises(
        InputError, match=r"many.npz: not a leg model file \(100,000 members; a leg model has 13, at most 64"
    ):
        leg_model.LegModel.load(path)


def test_a_leg_model_larger_than_256_mib_is_refused_before_it_is_opened(tmp_path, monkeypatch):
    import zipfile

    from datmo_cli.base.errors import InputError
    from datmo_cli.perception import leg_model

    path = tmp_path / "huge.npz"
    with open(path, "wb") as f:
        f.truncate((256 << 20) + 1)

    def opened(*args, **kwargs):
        raise AssertionError("the file was opened as a zip")

    monkeypatch.setattr(zipfile, "ZipFile", opened)
    with pytest.raises(
        InputError, match=r"huge.npz: not a leg model file \(268,435,457 bytes; a leg model takes at most"
    ):
        leg_model.LegModel.load(path)


def test_the_packaged_leg_model_still_loads():
    from datmo_cli.perception import leg_model

    assert leg_model.LegModel.load(leg_model.DEFAULT_MODEL_PATH).n_trees > 0


def test_play_refuses_a_client_frame_over_1_mib_on_its_header_before_buffering_it():
    """A client's frame whose header declares 256 MiB: the connection is closed (1009, message too big) on the
    header alone; unbounded, the server waited for the 256 MiB to buffer them (1.45 GB RSS)."""
    import socket
    import struct

    pytest.importorskip("foxglove")
    from websockets.sync.client import connect

    from datmo_cli import live

    server = live.LiveServer("127.0.0.1", 0)
    try:
        with connect(server.url, subprotocols=[live.SUBPROTOCOL], max_size=None, open_timeout=10) as ws:
            sock: socket.socket = ws.socket
            # a masked binary frame (FIN, opcode 2) declaring 256 MiB by its 64-bit length, then 16 bytes of it
            sock.sendall(bytes([0x82, 0x80 | 127]) + struct.pack(">Q", 256 << 20) + bytes(4) + bytes(16))
            with pytest.raises(Exception) as closed:
                while True:
                    ws.recv(timeout=10)
        assert getattr(getattr(closed.value, "rcvd", None), "code", None) == 1009, repr(closed.value)
    finally:
        server.close()


def ros2_bag_compressed_whole(folder: Path) -> Path:
    """A ROS 2 bag folder of five scans whose MCAP member is compressed whole (compression_mode: file)."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    from test_import_rosbag import SCAN, STORE2, messages

    w = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
    w.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    with w:
        conn = w.add_connection("/front", SCAN, typestore=STORE2)
        for topic, msgtype, t, make in messages():
            if topic == "/front":
                w.write(conn, t, STORE2.serialize_cdr(make(STORE2), msgtype))
    return folder


def test_a_bag_member_compressed_whole_is_decompressed_within_bounds(tmp_path):
    from datmo_cli.base.errors import InputError
    from datmo_cli.logs.importers import import_log

    bag = ros2_bag_compressed_whole(tmp_path / "whole")
    assert len(import_log(bag).run) == 5  # a sound one reads
    member = next(bag.glob("*.zstd"))
    member.write_bytes(zstd_stating(1 << 30))  # 1 GiB of zeros in about 32 KB
    with pytest.raises(InputError, match=r"decompresses to more than [\d,]+ bytes \(1,000 times its size plus 64 MiB"):
        import_log(bag)
