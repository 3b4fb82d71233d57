"""Reads bounded by what a sane file needs: a zstd chunk declaring 2 GiB took 2.1 GB; an lz4
chunk was decompressed whole before its size was checked; a leg model declaring a 3 GB array was loaded before
its shapes were; a 1 GB line of a .log.gz was read whole. Each is refused, or skipped with a warning, before the
memory is spent."""

from __future__ import annotations

import gzip
import io
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally

from datmo_cli.base.errors import InputError
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun, encode_scans

pytestmark = pytest.mark.cli

T0 = 1_600_000_000_000_000_000


def record(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def text(s: str) -> bytes:
    return struct.pack("<I", len(s)) + s.encode()


def mcap_with_chunk(compression: str, compressed: bytes, declared: int, crc: int = 0) -> bytes:
    """An MCAP whose scan messages lie in one chunk of `compressed` bytes that declares `declared` bytes
    uncompressed; its schema and channel at the top level, before it."""
    run = ScanRun(
        T0 + np.arange(3, dtype=np.int64) * 200_000_000,
        np.full((3, 91), 3.0, np.float32),
        ScanGeometry(-np.pi / 2, np.pi / 90, 91, 0.0, 8.0, 0.0, 0.2, "laser"),
    )
    schema = record(
        0x03, struct.pack("<H", 1) + text(types.LASERSCAN) + text("ros2msg") + text(types.schema_text(types.LASERSCAN))
    )
    channel = record(0x04, struct.pack("<HH", 1, 1) + text(mcapio.TOPIC_SCAN) + text("cdr") + struct.pack("<I", 0))
    chunk = record(
        0x06,
        struct.pack("<QQQI", T0, T0, declared, crc)
        + text(compression)
        + struct.pack("<Q", len(compressed))
        + compressed,
    )
    return (
        mcapio.MAGIC
        + record(0x01, text("ros2") + text("test"))
        + schema
        + channel
        + chunk
        + record(0x0F, struct.pack("<I", 0))
        + record(0x02, struct.pack("<QQI", 0, 0, 0))
        + mcapio.MAGIC
    ), encode_scans(run)


def messages(payloads: list[bytes]) -> bytes:
    return b"".join(record(0x05, struct.pack("<HIQQ", 1, i, T0 + i, T0 + i) + p) for i, p in enumerate(payloads))


def test_a_sound_handmade_chunk_reads(tmp_path):
    """The hand-made file is an MCAP the reader takes whole: only the bombs below are refused."""
    import zstandard

    _, payloads = mcap_with_chunk("", b"", 0)
    inner = messages(payloads)
    data, _ = mcap_with_chunk("zstd", zstandard.ZstdCompressor().compress(inner), len(inner))
    path = tmp_path / "sound.mcap"
    path.write_bytes(data)
    assert len(mcapio.read_run(path)) == 3


def test_a_zstd_chunk_declaring_2_gib_is_skipped_before_decompressing(tmp_path, monkeypatch):
    import zstandard

    _, payloads = mcap_with_chunk("", b"", 0)
    data, _ = mcap_with_chunk("zstd", zstandard.ZstdCompressor().compress(messages(payloads)), 2 << 30)
    path = tmp_path / "bomb.mcap"
    path.write_bytes(data)

    def spent(*args, **kwargs):
        raise AssertionError("a chunk declaring 2 GiB was decompressed")

    monkeypatch.setattr(zstandard.ZstdDecompressor, "decompress", spent)
    try:
        with pytest.warns(
            mcapio.CorruptLogWarning,
            match=r"declares 2,147,483,648 bytes uncompressed, more than a "
            r"chunk may hold \(268,435,456\)",
        ):
            log = mcapio.read_log(path, topics=None)
        assert log.corrupt_chunks == 1 and not log.has(mcapio.TOPIC_SCAN)
        result = CliRunner().invoke(cli, ["info", str(path)])
        assert result.exit_code == 0 and "declares 2,147,483,648 bytes" in result.stderr
    except BaseException:
        tally("decompression bombs", failed=True)
        raise
    tally("decompression bombs")


def test_an_lz4_chunk_is_decompressed_no_further_than_it_declares(tmp_path):
    import lz4.frame

    bomb = lz4.frame.compress(bytes(64 << 20))  # 64 MiB of zeros in about 260 kB
    data, _ = mcap_with_chunk("lz4", bomb, 1000)
    path = tmp_path / "bomb.mcap"
    path.write_bytes(data)
    tracemalloc.start()
    try:
        with pytest.warns(mcapio.CorruptLogWarning, match="decompresses to more than the 1,000 bytes its header says"):
            log = mcapio.read_log(path, topics=None)
        peak = tracemalloc.get_traced_memory()[1]
        assert log.corrupt_chunks == 1 and peak < 8 << 20, peak
    except BaseException:
        tally("decompression bombs", failed=True)
        raise
    finally:
        tracemalloc.stop()
    tally("decompression bombs")
    _, payloads = mcap_with_chunk("", b"", 0)
    inner = messages(payloads)
    sound = tmp_path / "sound.mcap"
    sound.write_bytes(mcap_with_chunk("lz4", lz4.frame.compress(inner), len(inner))[0])
    assert len(mcapio.read_run(sound)) == 3


def npy_header(shape: tuple, dtype: str = "<f8") -> bytes:
    """The magic and header of a .npy file (format 1.0) declaring an array of `shape`."""
    f = io.BytesIO()
    np.lib.format.write_array_header_1_0(f, {"descr": dtype, "fortran_order": False, "shape": shape})
    return f.getvalue()


def test_a_leg_model_declaring_a_3_gb_array_is_refused_before_loading(tmp_path, monkeypatch):
    from datmo_cli.perception import leg_model

    good = leg_model.DEFAULT_MODEL_PATH
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "threshold.npy":  # declares 400 million floats; holds eight
                data = npy_header((400_000_000,)) + bytes(64)
            dst.writestr(info.filename, data)

    def spent(*args, **kwargs):
        raise AssertionError("np.load called on a model declaring 3.2 GB")

    monkeypatch.setattr(np, "load", spent)
    try:
        with pytest.raises(
            InputError,
            match=r"bomb.npz: not a leg model file \(threshold.npy and the arrays before it "
            r"declare [\d,]+ bytes, more than a leg model takes \(268,435,456\)\)",
        ):
            leg_model.LegModel.load(path)
    except BaseException:
        tally("decompression bombs", failed=True)
        raise
    tally("decompression bombs")
    monkeypatch.undo()
    assert leg_model.LegModel.load(good).n_trees > 0


def test_a_long_line_in_a_gzipped_carmen_log_is_never_held_whole(tmp_path):
    ranges = " ".join(["3.0"] * 181)
    lines = [f"FLASER 181 {ranges} 1 2 0.5 1 2 0.5 {100 + 0.2 * k:.6f} host {100 + 0.2 * k:.6f}" for k in range(10)]
    path = tmp_path / "long.log.gz"
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines[:5]) + "\nFLASER " + "1.0 " * 4_000_000 + "\n" + "\n".join(lines[5:]) + "\n")
    from datmo_cli.logs.importers import import_log

    tracemalloc.start()
    try:
        res = import_log(path)
        peak = tracemalloc.get_traced_memory()[1]
        assert len(res.run) == 10 and peak < 12 << 20, peak  # the 16 MB line never held (nor split into words)
        assert f"{path}: skipped 1 malformed line (first at line 6)" in res.warnings
    except BaseException:
        tally("decompression bombs", failed=True)
        raise
    finally:
        tracemalloc.stop()
    tally("decompression bombs")
