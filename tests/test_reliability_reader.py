"""Reliability of reading logs: chunk CRCs, decompression errors and
malformed LaserScans give a warning and the sound data, or one line naming the file; never a traceback or a
silently wrong scan. Ends with a fuzz of the reader (byte flips, truncations, random bytes) and of the CLI.
"""

from __future__ import annotations

import struct
import tempfile
import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from datmo_cli.base.errors import DatmoError
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun, encode_scans
from datmo_cli.passes.streaming import LogStream

pytestmark = pytest.mark.cli

GEOM = ScanGeometry(-np.pi / 2, np.pi / 90, 91, 0.0, 8.0, 0.0, 0.2, "laser")
T0 = 1_600_000_000_000_000_000
N_SCANS = 60


def make_run(n: int = N_SCANS, geometry: ScanGeometry = GEOM) -> ScanRun:
    stamps = T0 + np.arange(n, dtype=np.int64) * 200_000_000
    ranges = np.random.default_rng(1).uniform(0.5, 7.5, (n, geometry.n_beams)).astype(np.float32)
    return ScanRun(stamps, ranges, geometry)


def write_payloads(path: Path, stamps, payloads: list[bytes], chunk_size: int = 1 << 20) -> Path:
    with mcapio.LogWriter(path, force=True, chunk_size=chunk_size) as w:
        w.write_many(mcapio.TOPIC_SCAN, types.LASERSCAN, stamps, payloads)
    return path


def write_log(path: Path, chunk_size: int = 8000) -> Path:
    """N_SCANS scans and as many odometry poses, in several zstd chunks."""
    run = make_run()
    odom = Odometry(run.stamps, np.linspace(0, 1, len(run)), np.zeros(len(run)), np.zeros(len(run)))
    with mcapio.LogWriter(path, force=True, chunk_size=chunk_size) as w:
        w.write_scans(run)
        w.write_odometry(odom)
    return path


def chunks(data: bytes) -> list[tuple[int, int, int]]:
    """(record start, compressed data start, compressed size) of each chunk of an MCAP file."""
    pos, out = 8, []
    while pos + 9 <= len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        body = pos + 9
        if op == 0x06:
            cpos = body + 32 + struct.unpack_from("<I", data, body + 28)[0]
            out.append((pos, cpos + 8, struct.unpack_from("<Q", data, cpos)[0]))
        elif op == 0x0F:
            break
        pos = body + length
    return out


def flipped(data: bytes, at: int, mask: int = 0x01) -> bytes:
    out = bytearray(data)
    out[at] ^= mask
    return bytes(out)


def run_cli(*args) -> tuple[int, list[str], str]:
    """(exit code, stderr lines, stdout) of `datmo ARGS`; fails on an uncaught exception (a traceback)."""
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    return result.exit_code, lines, result.stdout


def assert_one_error(code: int, lines: list[str], *texts: str) -> None:
    assert code != 0
    assert len(lines) == 1 and lines[0].startswith("datmo: error: "), lines
    for text in texts:
        assert text in lines[0], (text, lines[0])


def leftovers(folder: Path, keep: set[str]) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


# ------------------------------------------------------------------------- rows 5 and 10: corrupt chunks


@pytest.fixture
def log(tmp_path) -> Path:
    return write_log(tmp_path / "in.mcap")


def scans_of(path: Path) -> ScanRun:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mcapio.read_run(path)


@pytest.mark.parametrize("where", ["data", "zstd header", "crc field", "size field"])
@pytest.mark.parametrize("which", [0, 2])
def test_corrupt_chunk_is_skipped_counted_and_warned(tmp_path, log, where, which):
    data = log.read_bytes()
    start, cdata, size = chunks(data)[which]
    at = {"data": cdata + size // 2, "zstd header": cdata, "crc field": start + 9 + 24, "size field": start + 9 + 16}[
        where
    ]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, at, 0xFF if where == "zstd header" else 0x01))
    with pytest.warns(mcapio.CorruptLogWarning, match=r"bad.mcap: skipped 1 corrupt chunk\(s\)"):
        contents = mcapio.read_log(bad, topics=None)
    assert contents.corrupt_chunks == 1 and contents.chunks == len(chunks(data)) - 1
    intact = {int(t): r.tobytes() for t, r in zip(*_stamps_ranges(scans_of(log)), strict=True)}
    got = mcapio.run_from_log(contents)
    assert 0 < len(got) < N_SCANS  # the skipped chunk held scans; the others are read (channels from the summary)
    for t, r in zip(*_stamps_ranges(got), strict=True):
        assert intact[int(t)] == r.tobytes()


def _stamps_ranges(run: ScanRun):
    return run.stamps, list(run.ranges)


def test_flipped_byte_in_zstd_chunk_cli(tmp_path, log):
    data = log.read_bytes()
    _, cdata, size = chunks(data)[1]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, cdata + size // 3))
    kept = len(scans_of(bad))
    code, lines, out = run_cli("info", bad, "--json")
    assert code == 0 and len(lines) == 1 and lines[0].startswith("datmo: warning: ")
    assert str(bad) in lines[0] and "1 corrupt chunk(s)" in lines[0] and "CRC mismatch" in lines[0]
    import json

    info = json.loads(out)
    assert info["corrupt_chunks"] == 1 and info["corrupt_bytes"] > 0 and info["scan"]["scans"] == kept < N_SCANS
    # import keeps exactly the sound scans, bit for bit (it does not re-stamp the corrupt data with a fresh CRC)
    code, lines, _ = run_cli("import", bad, "-o", tmp_path / "imported.mcap")
    assert code == 0 and sum("corrupt chunk" in line for line in lines) == 1
    imported, sound = scans_of(tmp_path / "imported.mcap"), scans_of(bad)
    assert np.array_equal(imported.stamps, sound.stamps) and imported.ranges.tobytes() == sound.ranges.tobytes()
    assert bad.read_bytes() == flipped(data, cdata + size // 3)  # the input untouched


@pytest.mark.parametrize("command", ["info", "track", "import"])
def test_corrupt_zstd_frame_header_cli(tmp_path, log, command):
    data = log.read_bytes()
    _, cdata, _ = chunks(data)[0]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, cdata, 0xFF))
    out = tmp_path / "out.mcap"
    args = [command, bad] + ([] if command == "info" else ["-o", out])
    code, lines, _ = run_cli(*args)
    assert code == 0, lines
    assert any(
        line.startswith("datmo: warning: ") and str(bad) in line and "does not decompress" in line for line in lines
    ), lines
    if command != "info":
        assert 0 < len(scans_of(out)) < N_SCANS


def test_emulate_log_with_corrupt_chunk_serves_the_sound_scans(tmp_path, log):
    from datmo_cli.lms2xx.scan_sources import LogSource

    data = log.read_bytes()
    _, cdata, _ = chunks(data)[1]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, cdata, 0xFF))
    with pytest.warns(mcapio.CorruptLogWarning):
        source = LogSource(bad)
    assert 0 < len(source.run) < N_SCANS


def test_record_length_past_the_end_of_a_whole_file_is_called_corrupt(tmp_path, log):
    data = log.read_bytes()
    start, _, _ = chunks(data)[1]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, start + 8, 0x40))  # the chunk's length: 2^62 more
    with pytest.warns(mcapio.CorruptLogWarning, match=f"record at byte {start} runs past the end"):
        contents = mcapio.read_log(bad, topics=[mcapio.TOPIC_SCAN])
    assert contents.chunks == 1 and contents.bad_length_at == start


def test_chunk_whose_opcode_is_damaged_is_counted_from_the_summary(tmp_path, log):
    data = log.read_bytes()
    start, _, _ = chunks(data)[0]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(flipped(data, start, 0x06 ^ 0x07))  # read as a message index record: skipped
    with pytest.warns(mcapio.CorruptLogWarning, match="1 of the .* chunks the summary lists were not found"):
        contents = mcapio.read_log(bad, topics=[mcapio.TOPIC_SCAN])
    assert contents.corrupt_chunks == 1 and contents.chunks == len(chunks(data)) - 1


def test_message_log_time_beyond_int64_is_one_line(tmp_path):
    bad = tmp_path / "late.mcap"
    with mcapio.LogWriter(bad, chunk_size=1 << 20) as w:
        w.write_scans(make_run(3))
    from mcap.writer import Writer

    with open(bad, "wb") as f:  # the same scans with a log time past 2262 (a valid uint64)
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        sid = writer.register_schema(types.LASERSCAN, "ros2msg", types.schema_text(types.LASERSCAN).encode())
        cid = writer.register_channel(mcapio.TOPIC_SCAN, "cdr", sid)
        for i, p in enumerate(encode_scans(make_run(3))):
            writer.add_message(cid, (1 << 63) + i, p, 0)
        writer.finish()
    code, lines, _ = run_cli("info", bad)
    assert_one_error(code, lines, str(bad), "past the year 2262")


# ---------------------------------------------------------------------- rows 11, 12, 19: bad LaserScans


def _bad_log(tmp_path: Path, scan: int, patch, n: int = 8) -> Path:
    run = make_run(n)
    payloads = encode_scans(run)
    raw = bytearray(payloads[scan])
    patch(raw)
    payloads[scan] = bytes(raw)
    return write_payloads(tmp_path / "in.mcap", run.stamps, payloads)


@pytest.mark.parametrize("scan, n", [(3, 8), (0, 1)])
def test_absurd_frame_id_length(tmp_path, scan, n):
    def patch(raw):
        raw[12:16] = struct.pack("<I", 0xFFFFFFF0)

    path = _bad_log(tmp_path, scan, patch, n)
    for command in ("info", "track"):
        code, lines, _ = run_cli(command, path, *(["-o", tmp_path / "out.mcap"] if command == "track" else []))
        assert_one_error(code, lines, str(path), f"scan {scan}: frame_id length 4294967280 runs past the end")
    assert leftovers(tmp_path, {"in.mcap"}) == []


@pytest.mark.parametrize(
    "field, at, message",
    [
        ("ranges", 24 + 28, "4294967280 ranges run past the end"),
        ("intensities", 24 + 32 + 4 * GEOM.n_beams, "4294967280 intensities run past the end"),
    ],
)
def test_absurd_sequence_lengths(tmp_path, field, at, message):
    def patch(raw):
        raw[at : at + 4] = struct.pack("<I", 0xFFFFFFF0)

    path = _bad_log(tmp_path, 1, patch)
    code, lines, _ = run_cli("info", path)
    assert_one_error(code, lines, str(path), f"scan 1: {message}")


# track takes scan 0: a later scan stamped before 1970 goes back in time, which streaming refuses first
@pytest.mark.parametrize("command, scan", [("track", 0), ("import", 2), ("info", 2)])
def test_stamp_before_1970(tmp_path, command, scan):
    def patch(raw):
        raw[4:8] = struct.pack("<i", -(2**31))

    path = _bad_log(tmp_path, scan, patch)
    before = path.read_bytes()
    extra = [] if command == "info" else ["-o", tmp_path / "out.mcap"]
    code, lines, _ = run_cli(command, path, *extra)
    assert_one_error(code, lines, str(path), "header stamp before 1970 (sec = -2147483648)")
    if command != "import":  # the importer surveys the first scan of each size without counting
        assert f"scan {scan}" in lines[0]
    assert leftovers(tmp_path, {"in.mcap"}) == [] and path.read_bytes() == before


def test_nanosec_out_of_range(tmp_path):
    def patch(raw):
        raw[8:12] = struct.pack("<I", 4_000_000_000)

    path = _bad_log(tmp_path, 7, patch)  # the last scan: its later stamp makes none go back in time
    code, lines, _ = run_cli("track", path, "-o", tmp_path / "out.mcap")
    assert_one_error(code, lines, str(path), "scan 7: header stamp nanosec = 4000000000 is not below 10^9")


@pytest.mark.parametrize(
    "field, value", [("angle_increment", np.nan), ("angle_min", np.nan), ("range_max", np.nan), ("range_min", -np.inf)]
)
@pytest.mark.parametrize("scan", [0, 4])
def test_non_finite_geometry_names_the_field(tmp_path, field, value, scan):
    # after the 4-byte CDR header, stamp, frame_id length and "laser\0" padded to 8 bytes: 7 float32s from byte 24
    at = 24 + {"angle_min": 0, "angle_increment": 8, "range_min": 20, "range_max": 24}[field]

    def patch(raw):
        raw[at : at + 4] = struct.pack("<f", value)

    path = _bad_log(tmp_path, scan, patch)
    code, lines, _ = run_cli("track", path, "-o", tmp_path / "out.mcap")
    assert_one_error(code, lines, str(path), f"scan {scan}: {field} is {float(np.float32(value))}")
    assert "geometry changes" not in lines[0]


def test_decode_scan_block_numbers_scans_from_the_block_start(tmp_path):
    run = make_run(4)
    payloads = encode_scans(run)
    raw = bytearray(payloads[1])
    raw[4:8] = struct.pack("<i", -1)
    payloads[1] = bytes(raw)
    with pytest.raises(DatmoError, match=r"x.mcap: bad LaserScan message on /scan: scan 1025: header stamp"):
        mcapio.decode_scan_block(Path("x.mcap"), payloads, first=1024)


# ------------------------------------------------------------------------------------------- no beams


def test_emulate_log_with_zero_beams(tmp_path):
    g = ScanGeometry(-np.pi / 2, np.pi / 180, 0, 0.0, 8.0)
    run = make_run(5, g)
    path = write_payloads(tmp_path / "empty.mcap", run.stamps, encode_scans(run))
    code, lines, _ = run_cli("emulate", "--log", path)
    assert_one_error(code, lines, str(path), "no beams")


# ------------------------------------------------------------------------------------------------ fuzz


@cache
def base_log() -> tuple[bytes, dict[int, bytes]]:
    """The fuzz's intact log (bytes) and its scans {stamp: ranges bytes}."""
    folder = Path(tempfile.mkdtemp(prefix="datmo-fuzz-"))
    path = write_log(folder / "base.mcap", chunk_size=6000)
    run = mcapio.read_run(path)
    data = path.read_bytes()
    path.unlink()
    folder.rmdir()
    return data, {int(t): r.tobytes() for t, r in zip(run.stamps, run.ranges, strict=True)}


def _mutations():
    data, _ = base_log()
    size = len(data)
    flips = st.lists(st.tuples(st.integers(0, size - 1), st.integers(1, 255)), min_size=1, max_size=4)
    chunk_flips = st.lists(
        st.sampled_from([c[1] + k for c in chunks(data) for k in range(0, c[2], 7)]), min_size=1, max_size=2
    ).map(lambda ps: [(p, 0x10) for p in ps])
    return st.one_of(
        flips.map(lambda f: ("flip", f)),
        chunk_flips.map(lambda f: ("flip", f)),
        st.integers(0, size - 1).map(lambda n: ("cut", n)),
        st.tuples(flips, st.integers(0, size - 1)).map(lambda t: ("flip+cut", t)),
        st.binary(min_size=0, max_size=600).map(lambda b: ("random", b)),
        st.binary(min_size=0, max_size=600).map(lambda b: ("random after magic", b)),
    )


def mutate(kind: str, arg) -> bytes:
    data, _ = base_log()
    if kind == "flip":
        out = bytearray(data)
        for at, mask in arg:
            out[at] ^= mask
        return bytes(out)
    if kind == "cut":
        return data[:arg]
    if kind == "flip+cut":
        return mutate("flip", arg[0])[: arg[1]]
    return arg if kind == "random" else mcapio.MAGIC + arg


def check_scans(stamps, ranges, intact: dict[int, bytes], previous: int) -> int:
    """Every scan is an intact one, bit for bit, in the log's order; returns the last stamp."""
    for t, r in zip(np.asarray(stamps).tolist(), ranges, strict=True):
        assert t in intact and intact[t] == np.asarray(r, np.float32).tobytes(), f"altered scan at {t}"
        assert t > previous, "scans out of order or repeated"
        previous = t
    return previous


def read_every_way(path: Path, intact: dict[int, bytes]) -> None:
    """Read `path` as the commands do; DatmoError is a fine answer, any scan must be an intact one."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for reader in (_whole, _streamed, _payloads):
            try:
                reader(path, intact)
            except DatmoError:
                pass


def _whole(path: Path, intact: dict[int, bytes]) -> None:
    contents = mcapio.read_log(path, topics=None)
    mcapio.check_scan_channel(contents)
    run = mcapio.run_from_log(contents)
    check_scans(run.stamps, run.ranges, intact, -1)
    assert len(run) == contents.topics()[mcapio.TOPIC_SCAN].count


def _streamed(path: Path, intact: dict[int, bytes]) -> None:
    stream = LogStream(path)
    last, n = -1, 0
    for run in stream.scans(size=16):
        last = check_scans(run.stamps, run.ranges, intact, last)
        n += len(run)
    assert n == stream.n_scans


def _payloads(path: Path, intact: dict[int, bytes]) -> None:
    payloads = [p for _, _, p in mcapio.iter_messages(path, [mcapio.TOPIC_SCAN])]
    if payloads:
        run = mcapio.decode_scan_block(path, payloads)
        check_scans(run.stamps, run.ranges, intact, -1)


@settings(
    max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(mutation=_mutations())
def test_fuzz_mcap_reader_errors_or_intact_scans(tmp_path, mutation):
    _, intact = base_log()
    path = tmp_path / "fuzz.mcap"
    path.write_bytes(mutate(*mutation))
    try:
        read_every_way(path, intact)
    except BaseException:
        tally("mcap reader fuzz", failed=True)
        raise
    tally("mcap reader fuzz")


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(at=st.integers(0, 10**9), mask=st.integers(1, 255), command=st.sampled_from(["info", "track"]))
def test_fuzz_cli_on_flipped_logs_no_traceback(tmp_path, at, mask, command):
    data, _ = base_log()
    folder = Path(tempfile.mkdtemp(dir=tmp_path))
    path = folder / "in.mcap"
    bad = flipped(data, at % len(data), mask)
    path.write_bytes(bad)
    args = [command, path] + (["-o", folder / "out.mcap"] if command == "track" else [])
    try:
        code, lines, _ = run_cli(*args)
        if code != 0:
            assert_one_error(code, [line for line in lines if not line.startswith("datmo: warning:")], str(path))
            assert leftovers(folder, {"in.mcap"}) == []
        assert path.read_bytes() == bad
    except BaseException:
        tally("cli fuzz (info, track on flipped logs)", failed=True)
        raise
    tally("cli fuzz (info, track on flipped logs)")
