"""Reliability of what datmo reads: importers, scan-stamp order and ground truth.

Regression tests, through the CLI, for the issue's rows 7 (scan stamps that go backwards or repeat), 8 and
17 (ground-truth CSV with NaN/inf, an id twice in a frame, an unknown class, a binary file, a stamp beyond
int64), 20 (a FLASER log with a NUL-byte line) and 21 (a CSV with a byte-order mark, a RAWLASER field of view
of 0); then hypothesis fuzz of the CARMEN parser and the ROS bag importer (byte flips, truncations, random
bytes), counted with fuzzing.tally.

What "exactly the intact scans" means here:
- CARMEN text has no checksums, so a flipped byte can turn a line into a different line that is still
  valid (a digit into another digit). The promise: the scans out are exactly those of the valid laser lines
  of the mutated text, read by a reference reading of the format written here (no scan from a line the
  format refuses, none lost, none altered on the way), and every line the mutation did not touch gives
  its original numbers.
- ROS 1 bags and ROS 2 bags hold no checksum of a message either: a flipped byte inside a scan's own bytes
  can change that scan and nothing can tell. The promise: an error, or scans each equal to an original
  scan (stamp, ranges, intensities), each at most once, in time order, except that the scans whose
  serialised bytes hold a flipped byte may come out changed.
"""

from __future__ import annotations

import hashlib
import io
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
import synthetic_logs as syn
from click.testing import CliRunner
from fuzzing import tally
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_evaluate import gt_csv_text
from test_import_carmen import flaser
from test_import_rosbag import ODOM, SCAN, STORE1, STORE2, _odom, _scan, write_ros1, write_ros2

from datmo_cli.base.errors import DatmoError
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.importers import import_log
from datmo_cli.logs.scan import ScanGeometry, ScanRun

pytestmark = pytest.mark.cli


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(result, *needles: str) -> str:
    """The one error line of a refused command (non-zero exit, no traceback), holding every needle."""
    assert result.exit_code not in (0, None), result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("datmo: error: ")]
    assert len(errors) == 1, result.output
    for needle in needles:
        assert needle in errors[0], errors[0]
    return errors[0]


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def leftovers(folder: Path, *keep: Path) -> list[str]:
    """Files in `folder` other than `keep` (outputs or hidden temporary files left behind)."""
    return sorted(p.name for p in folder.rglob("*") if p.is_file() and p not in keep)


# ------------------------------------------------------------------------- scan stamps out of order


N_SCANS = 30
GEOMETRY = ScanGeometry(-np.pi / 2, np.pi / 180, 181, 0.0, 8.0)


def disordered_log(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A scan log whose header stamps repeat (scan 10 has scan 5's) and go back (scans 20 and 21 swapped),
    its log times increasing; (stamps, ranges) as written."""
    stamps = (np.arange(N_SCANS) * 100_000_000 + 10**9).astype(np.int64)
    stamps[10] = stamps[5]
    stamps[20], stamps[21] = stamps[21], stamps[20]
    ranges = np.linspace(1, 5, 181, dtype=np.float32)[None, :] + np.arange(N_SCANS, dtype=np.float32)[
        :, None
    ] * np.float32(0.01)
    with mcapio.LogWriter(path) as w:
        cid = w.channel(mcapio.TOPIC_SCAN, types.LASERSCAN)
        w.write_ids(
            cid,
            (np.arange(N_SCANS) * 100_000_000 + 10**9).astype(np.int64),
            mcapio.encode_scans(ScanRun(stamps, ranges, GEOMETRY)),
        )
    return stamps, ranges


def test_import_writes_scans_in_time_order_and_drops_repeated_stamps(tmp_path):
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    stamps, ranges = disordered_log(src)
    digest = sha(src)
    result = invoke("import", src, "-o", out)
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if line.startswith("datmo: warning: ")]
    assert warnings == [
        f"datmo: warning: {src}: scan stamps not increasing: of 30 scans, 1 stamped before an "
        "earlier one (first at scan 21), written in time order; 1 repeat the stamp of another "
        "(first at scan 10), dropped"
    ]
    run = mcapio.read_run(out)
    assert len(run) == N_SCANS - 1 and np.all(np.diff(run.stamps) > 0)
    assert run.stamps.tolist() == sorted(set(stamps.tolist()))
    for stamp, row in zip(run.stamps.tolist(), run.ranges, strict=True):
        first = int(np.flatnonzero(stamps == stamp)[0])  # a repeated stamp keeps the first scan
        np.testing.assert_array_equal(row, ranges[first])
    assert sha(src) == digest


def test_bag_import_orders_scans_the_same_way(tmp_path):
    order = [0, 1, 2, 4, 3, 5, 5, 6]  # scan 4 before 3; 5 twice
    msgs = [
        ("/scan", SCAN, 10**9 + k * 10**8, lambda s, k=k, i=i: _scan(s, 10**9 + order[i] * 10**8, 8, "laser", 1.0 + i))
        for k, i in enumerate(range(len(order)))
    ]
    result = import_log(write_ros1(tmp_path / "b.bag", msgs))
    assert result.run.stamps.tolist() == [10**9 + k * 10**8 for k in range(7)]
    assert result.run.ranges[:, 0].tolist() == [1, 2, 3, 5, 4, 6, 8]  # scan 6 (the second 5) dropped
    assert result.warnings == [
        f"{tmp_path / 'b.bag'}: scan stamps not increasing: of 8 scans, 1 stamped before "
        "an earlier one (first at scan 4), written in time order; 1 repeat the stamp of "
        "another (first at scan 6), dropped"
    ]


@pytest.mark.parametrize("command", ["segment", "features", "track", "run"])
def test_stages_refuse_a_log_whose_scan_stamps_go_backwards(tmp_path, command):
    """Refused before anything is written (the tracker's time would stand still or run back); the message
    names the file, the count and the first scan, and the way out."""
    src = tmp_path / "in.mcap"
    disordered_log(src)
    digest = sha(src)
    out = tmp_path / ("out" if command == "run" else "out.mcap")
    result = invoke(command, src, "-o", out)
    one_line_error(
        result, f"{src}: scan stamps go backwards or repeat at 2 of 30 scans (first at scan 10)", "datmo import"
    )
    assert sha(src) == digest
    assert not [name for name in leftovers(tmp_path, src) if name.endswith((".mcap", ".tmp"))]


def test_the_imported_log_is_taken(tmp_path):
    src, fixed, out = tmp_path / "in.mcap", tmp_path / "fixed.mcap", tmp_path / "seg.mcap"
    disordered_log(src)
    assert invoke("import", src, "-o", fixed).exit_code == 0
    result = invoke("segment", fixed, "-o", out)
    assert result.exit_code == 0, result.output
    assert mcapio.summary(out).topics()[mcapio.TOPIC_SEGMENTS].count == N_SCANS - 1


# ------------------------------------------------------------------ rows 8, 17, 21: ground-truth CSV


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    path = tmp_path_factory.mktemp("reliability") / "run.mcap"
    syn.write(path)
    return path


S0 = int(syn.STAMPS[0])


@pytest.mark.parametrize(
    "text, needles",
    [
        (f"stamp_ns,id,x,y\n{S0},1,nan,0\n", ["line 2", "x is nan", "finite"]),
        (f"stamp_ns,id,x,y\n{S0},1,0,0\n{S0},2,1,-inf\n", ["line 3", "y is -inf"]),
        (f"stamp_ns,id,x,y\n{S0},1,0,0\n{S0},1,2,2\n", ["line 3", "id 1 again at stamp_ns", "first at line 2"]),
        (f"stamp_ns,id,x,y,class\n{S0},1,0,0,dog\n", ["line 2", "unknown class 'dog'"]),
        (f"stamp_ns,id,x,y,class\n{S0},1,0,0,7\n", ["line 2", "unknown class '7'"]),
        ("stamp_ns,id,x,y\n99999999999999999999,1,0,0\n", ["line 2", "outside int64"]),
        ("stamp_ns,id,x,y\n-5,1,0,0\n", ["line 2", "outside int64"]),
        ("stamp_ns,id,x,y\n1.5e9,1,0,0\n", ["line 2", "stamp_ns '1.5e9' is not an integer"]),
    ],
)
def test_ground_truth_csv_refused_with_its_line(tmp_path, tracked, text, needles):
    path = tmp_path / "gt.csv"
    path.write_text(text)
    one_line_error(invoke("evaluate", tracked, "--gt", path), f"{path}: ", *needles)


@pytest.mark.parametrize(
    "data, needle",
    [
        (bytes(range(256)) * 8, "binary data (a NUL byte at byte 0)"),
        (b"stamp_ns,id,x,y\n1,1,\xff\xfe,0\n", "not UTF-8 text (byte 20)"),
        (b'stamp_ns,id,x,y\n1,1,"0\n' + b"9" * 200_000 + b"\n", "not CSV"),
    ],
)
def test_ground_truth_that_is_not_csv_text_refused(tmp_path, tracked, data, needle):
    path = tmp_path / "gt.csv"
    path.write_bytes(data)
    one_line_error(invoke("evaluate", tracked, "--gt", path), f"{path}: ", needle)


def test_ground_truth_csv_with_a_byte_order_mark_reads(tmp_path, tracked):
    import json

    plain, bom = tmp_path / "plain.csv", tmp_path / "bom.csv"
    text = gt_csv_text(round_to_ms=True)
    plain.write_text(text, encoding="utf-8")
    bom.write_text(text, encoding="utf-8-sig")
    assert bom.read_bytes().startswith(b"\xef\xbb\xbf")
    a, b = (invoke("evaluate", tracked, "--gt", p, "--format", "json") for p in (plain, bom))
    assert a.exit_code == 0 and b.exit_code == 0, b.output
    assert json.loads(a.output)["scores"] == json.loads(b.output)["scores"]
    assert json.loads(b.output)["scores"]["person"]["num_objects"] == 95


# ------------------------------------------------------------------ rows 20, 21: CARMEN lines


def test_flaser_log_with_a_nul_line_imports_skipping_the_bad_lines(tmp_path):
    ranges = [np.round(1.0 + 0.1 * i + 0.01 * np.arange(181), 2) for i in range(20)]
    lines = [flaser(r, 100.0 + i) for i, r in enumerate(ranges)]
    lines[5] = "\x00" * 300
    lines[8] = "FLASER 3 garbage"
    lines[11] = "random words here"
    lines[14] = lines[14][:40]
    src, out = tmp_path / "nul.log", tmp_path / "nul.mcap"
    src.write_text("\n".join(lines) + "\n")
    result = invoke("import", src, "-o", out)
    assert result.exit_code == 0, result.output
    assert f"datmo: warning: {src}: skipped 4 malformed lines (first at line 6, 9, 12)" in result.output
    run = mcapio.read_run(out)
    good = [i for i in range(20) if i not in (5, 8, 11, 14)]
    assert run.stamps.tolist() == [round((100.0 + i) * 1e9) for i in good]
    np.testing.assert_array_equal(run.ranges, np.array([ranges[i] for i in good], np.float32))


def rawlaser_line(ranges, t: float, fov: str = "3.14159", res: str = "0.0174533") -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    return f"RAWLASER1 0 -1.5708 {fov} {res} 8.0 0.01 0 {len(ranges)} {r} 0 {t:.6f} host {t:.6f}"


def test_rawlaser_field_of_view_of_zero_is_a_malformed_line(tmp_path):
    lines = [rawlaser_line([1.0 + 0.5 * i] * 181, 10.0 + i) for i in range(8)]
    lines[2] = rawlaser_line([3.0] * 181, 12.0, fov="0")
    lines[3] = rawlaser_line([4.0] * 181, 13.0, fov="-3.14159")
    lines[4] = rawlaser_line([5.0] * 181, 14.0, fov="nan")
    lines[5] = rawlaser_line([6.0] * 181, 15.0, res="0")
    src, out = tmp_path / "raw.log", tmp_path / "raw.mcap"
    src.write_text("\n".join(lines) + "\n")
    result = invoke("import", src, "-o", out)
    assert result.exit_code == 0, result.output
    assert f"{src}: skipped 4 malformed lines (first at line 3, 4, 5)" in result.output
    run = mcapio.read_run(out)
    assert run.ranges[:, 0].tolist() == [1.0, 1.5, 4.0, 4.5]
    assert run.geometry.angle_increment == pytest.approx(0.0174533)


def test_rawlaser_with_only_zero_fields_of_view_is_refused(tmp_path):
    src = tmp_path / "raw.log"
    src.write_text("\n".join(rawlaser_line([1.0] * 9, 10.0 + i, fov="0") for i in range(3)) + "\n")
    one_line_error(
        invoke("import", src, "-o", tmp_path / "out.mcap"), f"{src}: no laser scans", "skipped 3 malformed lines"
    )
    assert leftovers(tmp_path, src) == []


# ------------------------------------------------------------------ fuzz: shared strategies


def mutations(size: int):
    """Byte flips (1-3), a truncation, or random bytes in place of a file of `size` bytes."""
    return st.one_of(
        st.tuples(
            st.just("flip"), st.lists(st.tuples(st.integers(0, size - 1), st.integers(0, 7)), min_size=1, max_size=3)
        ),
        st.tuples(st.just("cut"), st.integers(0, size - 1)),
        st.tuples(st.just("random"), st.binary(max_size=3000)),
    )


def mutate(data: bytes, mutation) -> tuple[bytes, set[int]]:
    """(mutated bytes, offsets of the original bytes that changed; for a cut, those from the cut on)."""
    kind, arg = mutation
    if kind == "flip":
        out = bytearray(data)
        for pos, bit in arg:
            out[pos] ^= 1 << bit
        return bytes(out), {pos for pos, _ in arg if out[pos] != data[pos]}
    if kind == "cut":
        return data[:arg], set(range(arg, len(data)))
    return arg, set(range(len(data)))


FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
# rosbags compiles its message readers for every bag it opens (about 0.2 s a case)
BAG_FUZZ = settings(FUZZ, max_examples=40)


# ------------------------------------------------------------------ fuzz: CARMEN parser


def carmen_text(kind: str) -> tuple[bytes, list[tuple[int, int, np.ndarray, float]]]:
    """A small CARMEN log of one laser message (FLASER with ODOM, RAWLASER1 or ROBOTLASER1) and its scans:
    (first byte, end byte after the newline, ranges, ipc stamp) per laser line. FLASER readings include
    SICK's 81.91 m no-return code on every scan, so no single line decides the no-return limit."""
    rng = np.random.default_rng(7)
    head = ["# a CARMEN log made by the test", "PARAM laser_front_laser_flipped off", "PARAM robot_length 0.5"]
    body, scans = [], []
    for i in range(10):
        r = np.array([float(f"{v:.2f}") for v in rng.uniform(0.5, 30.0, 24)])  # the numbers the text holds
        t = 1000.0 + 0.2 * i
        if kind == "FLASER":
            r[3] = 81.91
            body.append(f"ODOM {0.1 * i:.2f} 0.5 0.1 0.2 0.0 0.0 {t - 0.05:.6f} host {t:.6f}")
            body.append(flaser(r, t, pose=(0.1 * i, 0.5, 0.1)))
        elif kind == "RAWLASER1":
            body.append(rawlaser_line(r, t, fov="3.14159", res="0.136591"))
        else:
            rr = " ".join(f"{v:g}" for v in r)
            body.append(
                f"ROBOTLASER1 0 -1.570796 3.141593 0.136591 25.000000 0.1 0 24 {rr} 0 "
                f"3 4 0.25 3 4 0.25 0 0 0 0 0 {t:.6f} host {t:.6f}"
            )
        scans.append((r, t))
    lines = head + body + ["SYNC 1 2 3"]
    data = ("\n".join(lines) + "\n").encode()
    spans, pos = [], 0
    for line in lines:
        end = pos + len(line) + 1
        if line.startswith(kind):
            r, t = scans[len(spans)]
            spans.append((pos, end, r, t))
        pos = end
    return data, spans


def reference_scans(data: bytes) -> tuple[dict[str, list[tuple]], bool]:
    """The laser lines of CARMEN text as the format defines them (module docstring of importers.carmen):
    {message: [(ranges, ipc seconds, (start, step, stated max) or None)]}, and whether PARAM flips FLASER.
    Read as the importer reads text: UTF-8 with bad bytes replaced, universal newlines, white space."""
    out: dict[str, list[tuple]] = {}
    flipped = False
    for line in io.TextIOWrapper(io.BytesIO(data), encoding="utf-8", errors="replace", newline=None):
        tok = line.split()
        if not tok:
            continue
        name = tok[0]
        if name == "PARAM" and len(tok) >= 3 and tok[1] == "laser_front_laser_flipped":
            flipped = tok[2].lower() in ("1", "on", "yes", "true")
        try:
            if name in ("FLASER", "RLASER"):
                n = int(tok[1])
                if not (n >= 1 and n + 9 <= len(tok) <= n + 11):
                    continue
                v = np.array(tok[2 : n + 9], float)
                out.setdefault(name, []).append((v[:n], float(v[n + 6]), None))
            elif name in ("RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4", "ROBOTLASER1", "ROBOTLASER2"):
                start, fov, res, top = (float(x) for x in tok[2:6])
                n = int(tok[8])
                if not (
                    n >= 1
                    and len(tok) >= 10 + n
                    and math.isfinite(start)
                    and math.isfinite(top)
                    and 0 < fov <= 2 * math.pi * 1.001
                    and 0 < res <= fov * 1.001
                ):
                    continue
                ranges = np.array(tok[9 : 9 + n], float)
                n_rem = int(tok[9 + n])
                rest = tok[10 + n + n_rem :]
                extra = 11 if name.startswith("ROBOT") else 0
                if n_rem < 0 or not (extra + 1 <= len(rest) <= extra + 3):
                    continue
                np.array(tok[10 + n : 10 + n + n_rem], float)
                nums = np.array(rest[: extra + 1], float)
                out.setdefault(name, []).append((ranges, float(nums[extra]), (start, res, top)))
        except (ValueError, IndexError):
            continue
    return out, flipped


def no_return_at(scans: list[tuple]) -> float:
    """docs/import.md's no-return limit: the stated maximum, else from the largest FLASER reading."""
    stated = scans[0][2][2] if scans[0][2] is not None else 0.0
    if stated > 0:
        return stated
    top = float(np.fmax.reduce([np.fmax.reduce(r) for r, _, _ in scans]))  # NaN readings ignored
    return 81.83 if top >= 81.83 - 1e-6 else 50.0 if top >= 50 else 32.767 if abs(top - 32.767) < 1e-6 else 81.83


def as_imported(ranges: np.ndarray, limit: float, flipped: bool) -> np.ndarray:
    r = np.where(ranges >= limit, np.inf, ranges)
    return (r[::-1] if flipped else r).astype(np.float32)


@pytest.mark.parametrize("kind", ["FLASER", "RAWLASER1", "ROBOTLASER1"])
def test_fuzz_carmen_parser(kind):
    data, spans = carmen_text(kind)
    folder = Path(tempfile.mkdtemp(prefix="datmo-fuzz-"))
    try:
        base = import_log(_write(folder, data))
        assert len(base.run) == len(spans)  # the intact text reads whole
        assert not [w for w in base.warnings if "malformed" in w or "timestamps" in w]

        @FUZZ
        @given(mutation=mutations(len(data)))
        def check(mutation):
            mutated, changed = mutate(data, mutation)
            ok = _carmen_case(_write(folder, mutated), mutated, changed, spans)
            tally("carmen fuzz", failed=not ok)
            assert ok

        check()
    finally:
        shutil.rmtree(folder)


def _write(folder: Path, data: bytes) -> Path:
    path = folder / "log.txt"
    path.write_bytes(data)
    return path


def _carmen_case(path: Path, mutated: bytes, changed: set[int], spans) -> bool:
    ref, flipped = reference_scans(mutated)
    streams = [name for name, scans in ref.items() if scans]
    layouts = {(len(r), g) for name in streams for r, _, g in ref[name]}
    expect_scans = len(streams) == 1 and len(layouts) == 1
    try:
        result = import_log(path)
    except DatmoError:
        return not expect_scans  # refused only when no single laser stream of one layout is left
    if not expect_scans:
        return False
    scans = ref[streams[0]]
    limit = no_return_at(scans)
    flipped = flipped and streams[0] in ("FLASER", "RLASER")
    want = np.array([as_imported(r, limit, flipped) for r, _, _ in scans])
    if not (
        result.run.geometry.range_max == pytest.approx(limit)
        and result.run.ranges.shape == want.shape
        and np.array_equal(result.run.ranges, want, equal_nan=True)
    ):
        return False
    if not any("timestamps" in w for w in result.warnings):
        if result.run.stamps.tolist() != [round(t * 1e9) for _, t, _ in scans]:
            return False
    # every line the mutation left whole (with the newlines around it) gives its original numbers
    intact = [as_imported(r, limit, flipped) for a, b, r, _ in spans if not changed & set(range(a - 1, b))]
    out = [row for row in result.run.ranges]
    return all(any(np.array_equal(row, w) for row in out) for w in intact)


# ------------------------------------------------------------------ fuzz: ROS bag importer


def bag_messages():
    """Six scans of 16 beams (values unique per scan, intensities) and odometry, 10 Hz."""
    out = []
    for i in range(6):
        t = 10**9 + i * 10**8
        out.append(("/scan", SCAN, t, lambda s, t=t, i=i: _scan(s, t, 16, "laser", 1.0 + i, True)))
        out.append(("/odom", ODOM, t + 1, lambda s, t=t, i=i: _odom(s, t, 0.1 * i, 0.0)))
    return out


def bag_file(kind: str, folder: Path) -> tuple[Path, Path]:
    """(what to import, the file whose bytes are mutated), made in `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    if kind == "ros1":
        path = write_ros1(folder / "b.bag", bag_messages())
        return path, path
    bag = write_ros2(folder / "b2", bag_messages(), kind.removeprefix("ros2-"))
    return bag, next(p for p in bag.iterdir() if p.name != "metadata.yaml")


def original_scans(kind: str, data: bytes) -> list[tuple[int, np.ndarray, np.ndarray, int, int]]:
    """(stamp, ranges, intensities, first byte, end byte of its serialised message in the file)."""
    out = []
    for _, _, t, make in bag_messages():
        msg = make(STORE1 if kind == "ros1" else STORE2)
        if not hasattr(msg, "ranges"):
            continue
        raw = bytes(STORE1.serialize_ros1(msg, SCAN) if kind == "ros1" else STORE2.serialize_cdr(msg, SCAN))
        at = data.find(raw)
        assert at >= 0 and data.find(raw, at + 1) < 0
        out.append((t, np.asarray(msg.ranges, np.float32), np.asarray(msg.intensities, np.float32), at, at + len(raw)))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_fuzz_rosbag_importer(kind):
    folder = Path(tempfile.mkdtemp(prefix="datmo-fuzz-"))
    try:
        src, target = bag_file(kind, folder / "orig")
        data = target.read_bytes()
        originals = original_scans(kind, data)
        assert len(import_log(src).run) == len(originals)

        @BAG_FUZZ
        @given(mutation=mutations(len(data)))
        def check(mutation):
            mutated, changed = mutate(data, mutation)
            work = folder / "case"
            shutil.rmtree(work, ignore_errors=True)
            shutil.copytree(src.parent, work)  # the bag (file, or folder with metadata.yaml) alone
            (work / target.relative_to(src.parent)).write_bytes(mutated)
            ok = _bag_case(work / src.name, originals, changed, mutation[0])
            tally("rosbag fuzz", failed=not ok)
            assert ok

        check()
    finally:
        shutil.rmtree(folder)


def _bag_case(path: Path, originals, changed: set[int], kind: str) -> bool:
    try:
        result = import_log(path)
    except DatmoError:
        return True
    run = result.run
    if not np.all(np.diff(run.stamps) > 0):
        return False
    hit = {i for i, (*_, a, b) in enumerate(originals) if kind == "flip" and changed & set(range(a, b))}
    used, changed_scans = set(), 0
    for k in range(len(run)):
        same = [
            i
            for i, (t, r, it, _, _) in enumerate(originals)
            if t == run.stamps[k]
            and np.array_equal(r, run.ranges[k], equal_nan=True)
            and (run.intensities.shape[1] == 0 or np.array_equal(it, run.intensities[k], equal_nan=True))
        ]
        if same and same[0] not in used:
            used.add(same[0])
        else:
            changed_scans += 1
    return changed_scans <= len(hit)
