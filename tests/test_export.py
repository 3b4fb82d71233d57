"""`datmo export`: per-scan tables out of processed logs. Rows are checked against /datmo/tracks and
/datmo/features as an independent reader (mcap_ros2) decodes them, in all three formats and for two files at
once; the header is pinned; what is held at once is counted on a tiled long log; stdout, the missing pyarrow
extra and bad inputs give what the project promises (one line, nothing written)."""

from __future__ import annotations

import csv
import io
import json
import math
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap_ros2.reader import read_ros2_messages

from datmo_cli import export
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.passes import pipeline

pytestmark = pytest.mark.cli

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"
CLASSES = {0: "unknown", 1: "person", 2: "circle object", 3: "rectangular object"}
MOBILITIES = {0: "static", 1: "dynamic", 2: "undefined"}
STATUSES = {0: "tentative", 1: "confirmed", 2: "coasting"}
HEADER = [
    "file",
    "scan",
    "stamp_ns",
    "frame_id",
    "kind",
    "id",
    "class",
    "mobility",
    "status",
    "x_m",
    "y_m",
    "vx_mps",
    "vy_mps",
    "world_x_m",
    "world_y_m",
    "world_vx_mps",
    "world_vy_mps",
    "size_m",
    "occluded",
    "age",
    "hits",
    "misses",
]
FEATURE_HEADER = [
    "segment",
    "first_beam",
    "last_beam",
    "n_points",
    "x_end_m",
    "y_end_m",
    "radius_m",
    "rho_m",
    "theta_rad",
    "r_acc",
    "probability",
]
SUFFIX = {"csv": ".csv", "ndjson": ".ndjson", "parquet": ".parquet"}


@pytest.fixture(scope="module")
def processed(tmp_path_factory) -> dict[str, Path]:
    """datmo run's outputs of a log with odometry (patrol) and one without (static)."""
    out = tmp_path_factory.mktemp("processed")
    paths = {}
    for name in ("patrol", "static"):
        paths[name] = out / f"{name}.mcap"
        pipeline.process_file(SAMPLES / f"{name}.mcap", paths[name])
    return paths


def invoke(*args: str, input: bytes | None = None):
    return CliRunner().invoke(cli, ["export", *args], input=input)


# ------------------------------------------------------------------------------ reference and reading back


def f32(v) -> float | None:
    """A float column's value as the float32 it stands for; None for an empty value (NaN)."""
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(np.float32(v))


def stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def reference_tracks(path: Path, name: str) -> list[dict]:
    """Every track state of /datmo/tracks, decoded by mcap_ros2, as the export's rows."""
    rows = []
    for scan, m in enumerate(read_ros2_messages(str(path), topics=[mcapio.TOPIC_TRACKS])):
        msg = m.ros_msg
        for t in msg.tracks:
            rows.append(
                {
                    "file": name,
                    "scan": scan,
                    "stamp_ns": stamp(msg.header),
                    "frame_id": msg.header.frame_id,
                    "kind": "track",
                    "id": t.id,
                    "class": CLASSES[t.classification],
                    "mobility": MOBILITIES[t.mobility],
                    "status": STATUSES[t.status],
                    "x_m": f32(t.x),
                    "y_m": f32(t.y),
                    "vx_mps": f32(t.vx),
                    "vy_mps": f32(t.vy),
                    "world_x_m": f32(t.world_x),
                    "world_y_m": f32(t.world_y),
                    "world_vx_mps": f32(t.world_vx),
                    "world_vy_mps": f32(t.world_vy),
                    "size_m": f32(t.size),
                    "occluded": bool(t.occluded),
                    "age": t.age,
                    "hits": t.hits,
                    "misses": t.misses,
                }
            )
    return rows


def reference_features(path: Path, name: str) -> list[dict]:
    """Every line, circle, blob or point and leg of /datmo/features (mcap_ros2), as the export's rows: within a
    batch of messages the kinds come in that order, each in message order (one batch: under 1,000 scans)."""
    per_kind: dict[str, list[dict]] = {"lines": [], "circles": [], "blobs": [], "legs": []}
    empty = dict.fromkeys(HEADER[5:] + FEATURE_HEADER)
    for scan, m in enumerate(read_ros2_messages(str(path), topics=[mcapio.TOPIC_FEATURES])):
        msg = m.ros_msg
        common = {**empty, "file": name, "scan": scan, "stamp_ns": stamp(msg.header), "frame_id": msg.header.frame_id}
        for f in msg.lines:
            per_kind["lines"].append(
                {
                    **common,
                    "kind": "line",
                    "segment": f.segment,
                    "first_beam": f.first,
                    "last_beam": f.last,
                    "n_points": f.n_points,
                    "x_m": f32(f.x_ini),
                    "y_m": f32(f.y_ini),
                    "x_end_m": f32(f.x_end),
                    "y_end_m": f32(f.y_end),
                    "size_m": f32(f.length),
                    "rho_m": f32(f.rho),
                    "theta_rad": f32(f.theta),
                    "r_acc": f32(f.r_acc),
                }
            )
        for f in msg.circles:
            per_kind["circles"].append(
                {
                    **common,
                    "kind": "circle",
                    "segment": f.segment,
                    "first_beam": f.first,
                    "last_beam": f.last,
                    "n_points": f.n_points,
                    "x_m": f32(f.x),
                    "y_m": f32(f.y),
                    "radius_m": f32(f.radius),
                    "r_acc": f32(f.r_acc),
                }
            )
        for f in msg.blobs:
            per_kind["blobs"].append(
                {
                    **common,
                    "kind": "point" if f.kind == 1 else "blob",
                    "segment": f.segment,
                    "first_beam": f.first,
                    "last_beam": f.last,
                    "n_points": f.n_points,
                    "x_m": f32(f.x),
                    "y_m": f32(f.y),
                    "size_m": f32(f.size),
                }
            )
        for f in msg.legs:
            per_kind["legs"].append(
                {
                    **common,
                    "kind": "leg",
                    "segment": f.segment,
                    "first_beam": f.first,
                    "last_beam": f.last,
                    "n_points": f.n_points,
                    "x_m": f32(f.x),
                    "y_m": f32(f.y),
                    "size_m": f32(f.width),
                    "probability": f32(f.probability),
                }
            )
    return [r for rows in per_kind.values() for r in rows]


def typed(row: dict, kinds: dict[str, str]) -> dict:
    """A row read back from any format, each value as the reference holds it."""
    out = {}
    for name, kind in kinds.items():
        v = row[name]
        if v is None or v == "":
            out[name] = None
        elif kind == "float32":
            out[name] = f32(float(v))
        elif kind in ("int64", "uint32"):
            out[name] = int(v)
        elif kind == "bool":
            out[name] = v if isinstance(v, bool) else {"true": True, "false": False}[v]
        else:
            out[name] = v
    return out


def read_table(path: Path, fmt: str, features: bool = False) -> tuple[list[str], list[dict]]:
    """(column names, typed rows) of an exported table."""
    kinds = export.columns(features)
    if fmt == "csv":
        reader = csv.DictReader(io.StringIO(path.read_text()))
        rows = list(reader)
        names = list(reader.fieldnames)
    elif fmt == "ndjson":
        rows = [json.loads(line) for line in path.read_text().splitlines()]
        names = list(rows[0])
        assert all(list(r) == names for r in rows)
    else:
        import pyarrow.parquet as pq

        table = pq.read_table(path).drop_columns(["stamp"])  # Parquet's own: stamp_ns as a timestamp
        names, rows = table.schema.names, table.to_pylist()
    return names, [typed(r, kinds) for r in rows]


# --------------------------------------------------------------------------------------------------- tests


@pytest.mark.parametrize("fmt", export.FORMATS)
def test_two_files_rows_equal_the_decoded_tracks(processed, tmp_path, fmt):
    out = tmp_path / f"tracks{SUFFIX[fmt]}"
    files = [str(processed["patrol"]), str(processed["static"])]
    result = invoke(*files, "-o", str(out))
    assert result.exit_code == 0, result.output
    names, rows = read_table(out, fmt)
    assert names == HEADER
    expected = reference_tracks(processed["patrol"], files[0]) + reference_tracks(processed["static"], files[1])
    assert len(rows) == len(expected) > 1000
    assert rows == expected
    assert any(r["world_x_m"] is not None for r in rows[:100]) and all(r["world_x_m"] is None for r in rows[-100:])
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.parametrize("fmt", export.FORMATS)
def test_features_follow_every_files_tracks(processed, tmp_path, fmt):
    out = tmp_path / f"all{SUFFIX[fmt]}"
    logs = [processed["patrol"], processed["static"]]
    assert invoke(*map(str, logs), "--features", "-o", str(out)).exit_code == 0
    names, rows = read_table(out, fmt, features=True)
    assert names == HEADER + FEATURE_HEADER
    tracks = [{**r, **dict.fromkeys(FEATURE_HEADER)} for log in logs for r in reference_tracks(log, str(log))]
    features = [r for log in logs for r in reference_features(log, str(log))]
    assert {r["kind"] for r in features} >= {"line", "circle", "leg"}
    assert rows == tracks + features


def test_format_from_the_option_over_the_suffix(processed, tmp_path):
    out = tmp_path / "tracks.txt"
    assert invoke(str(processed["static"]), "-o", str(out), "--format", "ndjson").exit_code == 0
    assert json.loads(out.read_text().splitlines()[0])["file"] == str(processed["static"])
    jsonl = tmp_path / "tracks.jsonl"
    assert invoke(str(processed["static"]), "-o", str(jsonl)).exit_code == 0
    assert jsonl.read_bytes() == out.read_bytes()


def test_stdout_is_the_same_table(processed, tmp_path):
    out = tmp_path / "tracks.csv"
    assert invoke(str(processed["static"]), "-o", str(out)).exit_code == 0
    result = invoke(str(processed["static"]), "-o", "-", "-q")
    assert result.exit_code == 0
    assert result.stdout_bytes == out.read_bytes()
    nd = invoke(str(processed["static"]), "-o", "-", "--format", "ndjson", "-q")
    assert nd.exit_code == 0 and len(nd.stdout.splitlines()) == len(out.read_text().splitlines()) - 1
    assert not (Path.cwd() / "-").exists()


def test_parquet_to_stdout_is_refused_before_any_work(processed, monkeypatch):
    monkeypatch.setattr(export, "plan", lambda *a, **k: pytest.fail("read the inputs"))
    result = invoke(str(processed["static"]), "-o", "-", "--format", "parquet")
    assert result.exit_code == 1
    assert result.stdout == ""
    assert result.stderr.splitlines() == [
        "datmo: error: -o -: Parquet is not written to stdout; give a file name (or --format csv or ndjson)"
    ]


def test_missing_pyarrow_names_the_extra(processed, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # `import pyarrow` now raises ImportError
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    out = tmp_path / "tracks.parquet"
    result = invoke(str(processed["static"]), "-o", str(out))
    assert result.exit_code == 1
    assert result.stderr.splitlines() == [
        "datmo: error: writing Parquet needs pyarrow, which is not installed: pip install 'datmo-cli[parquet]'"
    ]
    assert list(tmp_path.iterdir()) == []
    assert invoke(str(processed["static"]), "-o", str(tmp_path / "tracks.csv")).exit_code == 0  # CSV needs none


def test_progress_counts_every_scan_once(processed):
    plan = export.plan([processed["patrol"], processed["static"]], features=True)
    assert plan.total(mcapio.TOPIC_TRACKS) == plan.total(mcapio.TOPIC_FEATURES) == 600
    seen: dict[str, int] = {}
    sink = export.sink_for(io.BytesIO(), "csv", True)
    export.export(plan, sink, features=True, block=64, progress=lambda t, n: seen.__setitem__(t, seen.get(t, 0) + n))
    assert seen == {mcapio.TOPIC_TRACKS: 600, mcapio.TOPIC_FEATURES: 600}


def tiled(src: Path, path: Path, times: int) -> Path:
    """A log whose /datmo/tracks is `src`'s repeated `times` times, one scan period apart, in chunks of 64 kB
    (the short and the long log both hold many: what a reader keeps of a chunk is the same)."""
    stamps, payloads = mcapio.read_messages(src, mcapio.TOPIC_TRACKS)
    span = int(stamps[-1] - stamps[0]) + int(np.median(np.diff(stamps)))
    with mcapio.LogWriter(path, chunk_size=64 << 10) as w:
        for k in range(times):
            w.write_many(mcapio.TOPIC_TRACKS, types.TRACKS, stamps + k * span, payloads)
    return path


class Recorder(io.RawIOBase):
    """A binary stream that keeps nothing: it counts its writes and the lines written."""

    def __init__(self) -> None:
        super().__init__()
        self.sizes: list[int] = []
        self.lines = 0

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:
        self.sizes.append(len(data))
        self.lines += bytes(data).count(b"\n")
        return len(data)


def test_memory_does_not_grow_with_the_log(processed, tmp_path):
    per_scan = max(
        len(cdr.decode(types.TRACKS, p)["tracks"])
        for p in mcapio.read_messages(processed["patrol"], mcapio.TOPIC_TRACKS)[1]
    )
    peaks, rows = {}, {}
    for times in (1, 5):
        log = tiled(processed["patrol"], tmp_path / f"tiled{times}.mcap", times)
        plan = export.plan([log])
        stream = Recorder()
        sink = export.sink_for(stream, "ndjson", False)
        tracemalloc.start()
        export.export(plan, sink, block=30)
        peaks[times] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert sink.batches == len(stream.sizes) == 10 * times  # one write per batch of 30 of the 300 scans
        assert sink.peak_rows <= 30 * per_scan  # rows held at once: one batch's
        rows[times] = sink.rows
        assert stream.lines == sink.rows
    assert rows[5] == 5 * rows[1]
    assert peaks[5] < 1.5 * peaks[1]  # what the rows of the whole log would hold grows fivefold


def test_parquet_writes_a_row_group_per_batch(processed, tmp_path):
    import pyarrow.parquet as pq

    log = tiled(processed["patrol"], tmp_path / "tiled.mcap", 4)
    with open(tmp_path / "t.parquet", "wb") as f:
        sink = export.sink_for(f, "parquet", False)
        export.export(export.plan([log]), sink, block=100)
        sink.close()
    meta = pq.ParquetFile(tmp_path / "t.parquet").metadata
    assert meta.num_row_groups == sink.batches == 12
    assert meta.num_rows == sink.rows and max(meta.row_group(i).num_rows for i in range(12)) == sink.peak_rows


def test_inputs_checked_before_anything_is_written(processed, tmp_path):
    out = tmp_path / "t.csv"
    raw = SAMPLES / "hall.mcap"
    result = invoke(str(processed["static"]), str(raw), "-o", str(out))
    assert result.exit_code == 1
    assert result.stderr.splitlines() == [
        f"datmo: error: {raw}: no messages on /datmo/tracks; run datmo track (or datmo run) first"
    ]
    assert list(tmp_path.iterdir()) == []
    tracks_only = tmp_path / "tracks-only.mcap"
    with mcapio.LogWriter(tracks_only) as w:
        w.copy_from(processed["static"], exclude=[t for t in mcapio.PRODUCER if t != mcapio.TOPIC_TRACKS])
    result = invoke(str(tracks_only), "--features", "-o", str(out))
    assert result.exit_code == 1 and "no messages on /datmo/features; run datmo features" in result.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["-o", "{dir}/t.txt"], "{dir}/t.txt: cannot tell the format from the suffix '.txt'"),
        (["-o", "{static}", "--format", "csv", "--force"], "{static}: the output would overwrite the input"),
        (["-o", "{dir}/exists.csv"], "{dir}/exists.csv: exists; use --force to overwrite it"),
        (["-o", "{dir}/none/t.csv"], "{dir}/none: output folder does not exist"),
    ],
)
def test_bad_outputs_are_one_line(processed, tmp_path, args, message):
    (tmp_path / "exists.csv").write_text("keep")
    fill = {"dir": tmp_path, "static": processed["static"]}
    result = invoke(str(processed["static"]), *[a.format(**fill) for a in args])
    assert result.exit_code != 0
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: " + message.format(**fill))
    assert (tmp_path / "exists.csv").read_text() == "keep"
    assert not list(tmp_path.glob(".*.tmp"))


def test_force_replaces_an_existing_table(processed, tmp_path):
    out = tmp_path / "t.csv"
    out.write_text("old")
    assert invoke(str(processed["static"]), "-o", str(out), "--force").exit_code == 0
    assert out.read_text().startswith(",".join(HEADER) + "\n")


def damaged(data, payload: bytes) -> bytearray:
    """`payload` cut, with 1-8 bytes flipped, or replaced by random bytes (hypothesis draws which)."""
    p = bytearray(payload)
    how = data.draw(st.sampled_from(["cut", "flip", "random"]))
    if how == "cut":
        return p[: data.draw(st.integers(0, len(p) - 1))]
    if how == "flip":
        for _ in range(data.draw(st.integers(1, 8))):
            p[data.draw(st.integers(0, len(p) - 1))] ^= data.draw(st.integers(1, 255))
        return p
    return bytearray(data.draw(st.binary(max_size=200)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_damaged_tracks_messages_are_one_line(processed, tmp_path, data):
    """A Tracks payload cut, flipped or replaced: exported as it decodes, or refused in one line naming the
    file and the message; never a traceback, never a partial output."""
    stamps, payloads = mcapio.read_messages(processed["static"], mcapio.TOPIC_TRACKS)
    k = data.draw(st.integers(0, len(payloads) - 1))
    p = damaged(data, payloads[k])
    log, out = tmp_path / "damaged.mcap", tmp_path / "damaged.csv"
    out.unlink(missing_ok=True)
    with mcapio.LogWriter(log, force=True) as w:
        w.write_many(mcapio.TOPIC_TRACKS, types.TRACKS, stamps, payloads[:k] + [bytes(p)] + payloads[k + 1 :])
    result = invoke(str(log), "-o", str(out))
    lines = result.stderr.splitlines()
    ok = (result.exit_code == 0 and out.exists()) or (
        result.exit_code == 1
        and len(lines) == 1
        and lines[0].startswith(f"datmo: error: {log}: bad ")
        and f"message {k} on /datmo/tracks" in lines[0]
        and not out.exists()
    )
    tally("export: damaged Tracks messages", failed=not ok)
    assert ok, result.stderr
    assert not list(tmp_path.glob(".*.tmp"))


# ----------------------------------------------------------------------------------------- --ground-truth

GT_HEADER = ["stamp_ns", "id", "x", "y", "class"]
SIMULATED = ("hall", "crowd6", "corridor", "patrol")
# Figures that depend on the tracks in don't-care regions, which the CSV cannot carry (see datmo_cli/export.py).
REGION_FIGURES = {
    "num_predictions",
    "num_false_positives",
    "mota",
    "idf1",
    "idp",
    "precision",
    "hota",
    "deta",
    "assa",
    "ignored_hypotheses",
}
# counts and the figures made of them that motmetrics' continuity may move by a frame or two (see the test below)
CONTINUITY_COUNTS = {
    "num_matches",
    "num_misses",
    "num_switches",
    "num_fragmentations",
    "mostly_tracked",
    "partially_tracked",
    "mostly_lost",
}
CONTINUITY_FIGURES = CONTINUITY_COUNTS | {"recall", "idr", "motp", "loca"}


def channel_targets(path: Path, include_occluded: bool = False):
    """Targets and regions as evaluate reads them from /datmo/ground_truth."""
    from datmo_cli import evaluate as ev
    from datmo_cli.report import decode_channel

    stamps, payloads = mcapio.read_messages(path, mcapio.TOPIC_GROUND_TRUTH)
    truth = decode_channel(types.GROUND_TRUTH, payloads)
    return ev.ground_truth_frames(
        truth.stamps,
        truth.offsets["objects"],
        truth.items["objects"],
        truth.scalars.get("sensor_theta"),
        include_occluded=include_occluded,
    )


def ground_truth_rows(path: Path, fmt: str) -> list[dict]:
    """An exported ground-truth table's rows, in any format, as plain values (None for empty)."""
    if fmt == "csv":
        rows = list(csv.DictReader(io.StringIO(path.read_text())))
    elif fmt == "ndjson":
        rows = [json.loads(line) for line in path.read_text().splitlines()]
    else:
        import pyarrow.parquet as pq

        rows = pq.read_table(path).to_pylist()
    return [
        {
            "stamp_ns": int(r["stamp_ns"]),
            "id": None if r["id"] in (None, "") else int(r["id"]),
            "x": None if r["x"] in (None, "") else float(r["x"]),
            "y": None if r["y"] in (None, "") else float(r["y"]),
            "class": r["class"] or None,
        }
        for r in rows
    ]


@pytest.mark.parametrize("include_occluded", [False, True])
@pytest.mark.parametrize("name", SIMULATED)
def test_ground_truth_csv_reads_back_as_the_targets_evaluate_scores(tmp_path, name, include_occluded):
    from datmo_cli import evaluate as ev

    log, out = SAMPLES / f"{name}.mcap", tmp_path / "gt.csv"
    args = ["--include-occluded"] if include_occluded else []
    result = invoke(str(log), "--ground-truth", *args, "-o", str(out))
    assert result.exit_code == 0, result.output
    assert out.read_text().splitlines()[0] == ",".join(GT_HEADER)
    got, (want, _) = ev.read_ground_truth_csv(out), channel_targets(log, include_occluded)
    assert len(want.ids) > 100
    for attr in ("stamps", "offsets", "ids", "x", "y", "cls"):
        np.testing.assert_array_equal(getattr(got, attr), getattr(want, attr), err_msg=attr)


def test_a_scan_without_targets_is_a_stamp_only_row(tmp_path):
    """static.mcap's objects never move: no targets, and still every scan is a frame."""
    from datmo_cli import evaluate as ev

    out = tmp_path / "gt.csv"
    assert invoke(str(SAMPLES / "static.mcap"), "--ground-truth", "-o", str(out)).exit_code == 0
    stamps = mcapio.read_messages(SAMPLES / "static.mcap", mcapio.TOPIC_GROUND_TRUTH)[0]
    assert out.read_text().splitlines()[1:] == [f"{s},,,," for s in stamps.tolist()]
    frames = ev.read_ground_truth_csv(out)
    assert frames.stamps.tolist() == stamps.tolist() and len(frames.ids) == 0


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> dict[str, Path]:
    """datmo run's outputs of the simulated sample logs (they keep /datmo/ground_truth)."""
    out = tmp_path_factory.mktemp("simulated")
    paths = {}
    for name in SIMULATED:
        paths[name] = out / f"{name}.mcap"
        pipeline.process_file(SAMPLES / f"{name}.mcap", paths[name])
    return paths


@pytest.mark.parametrize("name", [pytest.param("hall", marks=pytest.mark.slow), "crowd6", "corridor", "patrol"])
def test_evaluate_scores_the_exported_csv_as_the_channel_but_for_dont_care_regions(simulated, tmp_path, name):
    """Scored against the exported CSV: every figure the same as against the channel, except that tracks
    in don't-care regions, which the CSV cannot carry, become false positives. (A region's track that the frame's
    own best assignment leaves unmatched is ignored against the channel, while motmetrics, which keeps a target's
    earlier match, may still give it that target against the CSV: so the counts of matches, misses and switches
    may differ in the odd frame, by at most 1 % of the targets.)"""
    from datmo_cli.commands.evaluate import score_file

    log, gt = simulated[name], tmp_path / "gt.csv"
    assert invoke(str(log), "--ground-truth", "-o", str(gt)).exit_code == 0
    channel = score_file(log, match_radius=0.3)["scores"]
    exported = score_file(log, gt_csv=gt, match_radius=0.3)["scores"]
    # a class whose only tracks the regions took out gets a row of its own, with no targets
    assert set(channel) <= set(exported)
    assert all(
        exported[cls]["num_objects"] == 0 < exported[cls]["num_false_positives"] for cls in set(exported) - set(channel)
    )
    for cls in channel:
        same = set(channel[cls]) - REGION_FIGURES
        for k in same:  # motmetrics sums the same distances in another order when the regions took tracks out
            want = channel[cls][k]
            if k in CONTINUITY_COUNTS and want is not None:
                assert abs(exported[cls][k] - want) <= 0.01 * channel[cls]["num_objects"], (cls, k)
            elif k in CONTINUITY_FIGURES and want is not None:
                assert exported[cls][k] == pytest.approx(want, rel=0.02), (cls, k)
            elif k not in CONTINUITY_FIGURES:
                assert exported[cls][k] == (want if want is None else pytest.approx(want, rel=1e-12)), (cls, k)
    ignored = channel["all"]["ignored_hypotheses"]
    assert ignored > 0 and exported["all"]["ignored_hypotheses"] == 0
    for key in ("num_predictions", "num_false_positives"):
        assert exported["all"][key] == channel["all"][key] + ignored, key


def test_without_the_dont_care_regions_the_channel_scores_as_the_exported_csv(simulated, tmp_path):
    """The channel's targets with its regions left out score exactly as the CSV: the regions are the only
    difference."""
    from datmo_cli import evaluate as ev
    from datmo_cli.commands.evaluate import score_file
    from datmo_cli.report import decode_channel

    log, gt = simulated["patrol"], tmp_path / "gt.csv"
    assert invoke(str(log), "--ground-truth", "-o", str(gt)).exit_code == 0
    targets, _ = channel_targets(log)
    tracks = decode_channel(types.TRACKS, mcapio.read_messages(log, mcapio.TOPIC_TRACKS)[1])
    hyps = ev.track_frames(tracks.stamps, tracks.offsets["tracks"], tracks.items["tracks"])
    assert ev.evaluate(targets, hyps, match_radius=0.3) == score_file(log, gt_csv=gt, match_radius=0.3)["scores"]


@pytest.mark.parametrize("fmt", ["ndjson", "parquet"])
def test_ground_truth_in_every_format_holds_the_csvs_rows(tmp_path, fmt):
    log = str(SAMPLES / "crowd6.mcap")
    assert invoke(log, "--ground-truth", "-o", str(tmp_path / "gt.csv")).exit_code == 0
    assert invoke(log, "--ground-truth", "-o", str(tmp_path / f"gt{SUFFIX[fmt]}")).exit_code == 0
    rows = ground_truth_rows(tmp_path / f"gt{SUFFIX[fmt]}", fmt)
    assert rows == ground_truth_rows(tmp_path / "gt.csv", "csv")
    assert len(rows) > 1000 and {r["class"] for r in rows} == {"person"}
    if fmt == "parquet":
        import pyarrow.parquet as pq

        assert pq.read_schema(tmp_path / "gt.parquet").names == [*GT_HEADER[:1], "stamp", *GT_HEADER[1:]]


def test_ground_truth_to_stdout_is_the_same_table(tmp_path):
    out = tmp_path / "gt.csv"
    assert invoke(str(SAMPLES / "patrol.mcap"), "--ground-truth", "-o", str(out)).exit_code == 0
    result = invoke(str(SAMPLES / "patrol.mcap"), "--ground-truth", "-o", "-", "-q")
    assert result.exit_code == 0 and result.stderr == ""
    assert result.stdout_bytes == out.read_bytes()


def test_ground_truth_streams_in_two_passes_each_scan_once():
    seen: dict[str, int] = {}
    sink = export.sink_for(io.BytesIO(), "csv", cols=export.GROUND_TRUTH_COLUMNS)
    export.export_ground_truth(
        SAMPLES / "hall.mcap", sink, block=64, progress=lambda stage, n: seen.__setitem__(stage, seen.get(stage, 0) + n)
    )
    assert seen == {"movers": 300, "targets": 300}
    assert sink.batches == 5 and sink.peak_rows < sink.rows  # 300 scans, 64 at a time


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["{hall}", "--ground-truth", "--features"],
            "--ground-truth with --features: the ground truth is a table of "
            "its own (stamp_ns,id,x,y,class); export it and the tracks with "
            "two commands",
        ),
        (
            ["{hall}", "{crowd6}", "--ground-truth"],
            "--ground-truth: give one FILE (evaluate --gt scores one log), not 2",
        ),
        (["{hall}", "--include-occluded"], "--include-occluded: only with --ground-truth (the targets no beam hits)"),
        (
            ["{csail}", "--ground-truth"],
            "{csail}: no messages on /datmo/ground_truth; only datmo simulate writes ground "
            "truth (annotate a real log as a stamp_ns,id,x,y CSV instead)",
        ),
    ],
)
def test_ground_truth_refusals_are_one_line(tmp_path, args, message):
    fill = {name: SAMPLES / f"{name}.mcap" for name in ("hall", "crowd6")} | {"csail": SAMPLES / "csail-excerpt.mcap"}
    result = invoke(*[a.format(**fill) for a in args], "-o", str(tmp_path / "gt.csv"))
    assert result.exit_code == 1
    assert result.stderr.splitlines() == ["datmo: error: " + message.format(**fill)]
    assert list(tmp_path.iterdir()) == []


def rewritten_ground_truth(path: Path, k: int, payload: bytes) -> Path:
    """hall.mcap's /datmo/ground_truth with message k's payload replaced, as the log at `path`."""
    stamps, payloads = mcapio.read_messages(SAMPLES / "hall.mcap", mcapio.TOPIC_GROUND_TRUTH)
    with mcapio.LogWriter(path, force=True) as w:
        w.write_many(
            mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH, stamps, payloads[:k] + [payload] + payloads[k + 1 :]
        )
    return path


def test_a_target_position_that_is_not_finite_is_one_line(tmp_path):
    payload = mcapio.read_messages(SAMPLES / "hall.mcap", mcapio.TOPIC_GROUND_TRUTH)[1][7]
    msg = cdr.decode(types.GROUND_TRUTH, payload)
    objects = msg["objects"].copy()
    person = np.flatnonzero(objects["classification"] == 1)[0]
    objects["x"][person] = np.inf
    log = rewritten_ground_truth(tmp_path / "inf.mcap", 7, cdr.encode(types.GROUND_TRUTH, {**msg, "objects": objects}))
    out = tmp_path / "gt.csv"
    result = invoke(str(log), "--ground-truth", "-o", str(out))
    assert result.exit_code == 1
    assert result.stderr.splitlines() == [
        f"datmo: error: {log}: /datmo/ground_truth message 7 holds a target position that is not a finite number"
    ]
    assert not out.exists() and not list(tmp_path.glob(".*.tmp"))


def test_a_ground_truth_stamp_that_does_not_increase_is_one_line(tmp_path):
    """Found by the fuzz test below: a flipped byte gave message 0 a later message's stamp, and evaluate --gt
    then refused the CSV (one id twice in one frame). Message k here gets message k - 2's stamp; k = 128 is the
    first of a block of 64."""
    from datmo_cli.base.errors import InputError

    stamps, payloads = mcapio.read_messages(SAMPLES / "hall.mcap", mcapio.TOPIC_GROUND_TRUTH)
    for k in (200, 128):
        msg = cdr.decode(types.GROUND_TRUTH, payloads[k])
        log = rewritten_ground_truth(
            tmp_path / "back.mcap", k, cdr.encode(types.GROUND_TRUTH, {**msg, "stamp_ns": int(stamps[k - 2])})
        )
        line = (
            f"{log}: /datmo/ground_truth message {k} has stamp_ns {stamps[k - 2]}, not after the previous "
            f"message's {stamps[k - 1]}"
        )
        with pytest.raises(InputError) as err:
            export.export_ground_truth(
                log, export.sink_for(io.BytesIO(), "csv", cols=export.GROUND_TRUTH_COLUMNS), block=64
            )
        assert str(err.value) == line
        out = tmp_path / "gt.csv"
        result = invoke(str(log), "--ground-truth", "-o", str(out))
        assert result.exit_code == 1 and result.stderr.splitlines() == [f"datmo: error: {line}"]
        assert not out.exists()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_damaged_ground_truth_messages_are_one_line(tmp_path, data):
    """A GroundTruth payload cut, flipped or replaced: exported as it decodes, to a CSV evaluate reads, or
    refused in one line naming the file; never a traceback, never a partial output."""
    from datmo_cli import evaluate as ev
    from datmo_cli.base.errors import InputError

    payloads = mcapio.read_messages(SAMPLES / "hall.mcap", mcapio.TOPIC_GROUND_TRUTH)[1]
    k = data.draw(st.integers(0, len(payloads) - 1))
    p = damaged(data, payloads[k])
    log, out = rewritten_ground_truth(tmp_path / "damaged.mcap", k, bytes(p)), tmp_path / "damaged.csv"
    out.unlink(missing_ok=True)
    result = invoke(str(log), "--ground-truth", "-o", str(out))
    lines = result.stderr.splitlines()
    if result.exit_code == 0 and out.exists():
        try:
            ev.read_ground_truth_csv(out)
            ok = True
        except InputError:
            ok = False
    else:
        ok = (
            result.exit_code == 1
            and len(lines) == 1
            and lines[0].startswith(f"datmo: error: {log}: ")
            and "/datmo/ground_truth" in lines[0]
            and not out.exists()
        )
    tally("export --ground-truth: damaged GroundTruth messages", failed=not ok)
    assert ok, result.stderr
    assert not list(tmp_path.glob(".*.tmp"))


# ------------------------------------------------------------------------------------- types (docs/export.md)

TYPE_CASES = {
    "odometry": ["patrol"],
    "no-odometry": ["static"],
    "no-odometry-first": ["static", "patrol"],
    "empty": ["empty"],
    "empty-first": ["empty", "static"],
}


@pytest.fixture(scope="module")
def typed_logs(processed, tmp_path_factory) -> dict[str, Path]:
    """The processed logs and an empty one: three scans whose Tracks and Features messages hold nothing."""
    empty = tmp_path_factory.mktemp("empty") / "empty.mcap"
    with mcapio.LogWriter(empty) as w:
        for k in range(3):
            t = 1_000_000_000 + k * 200_000_000
            w.write(
                mcapio.TOPIC_TRACKS, types.TRACKS, t, cdr.encode(types.TRACKS, {"stamp_ns": t, "frame_id": "laser"})
            )
            w.write(
                mcapio.TOPIC_FEATURES,
                types.FEATURES,
                t,
                cdr.encode(types.FEATURES, {"stamp_ns": t, "frame_id": "laser"}),
            )
    return {**processed, "empty": empty}


def exported(logs: list[Path], out: Path, features: bool) -> Path:
    result = invoke(*map(str, logs), "-o", str(out), *(["--features"] if features else []))
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize("features", [False, True], ids=["tracks", "features"])
@pytest.mark.parametrize("case", TYPE_CASES)
def test_every_format_reads_back_with_the_documented_types(typed_logs, tmp_path, case, features):
    """polars and pyarrow read CSV, NDJSON and Parquet with the schema of export.columns (given to the CSV and
    NDJSON readers, carried by Parquet), and every format holds the same table: one log or many, with odometry
    or without it in the first rows, with features or not, and for a log with no row at all."""
    import polars as pl
    import pyarrow.csv as pacsv
    import pyarrow.json as pajson
    import pyarrow.parquet as pq

    logs = [typed_logs[name] for name in TYPE_CASES[case]]
    paths = {fmt: exported(logs, tmp_path / f"t{SUFFIX[fmt]}", features) for fmt in export.FORMATS}
    schema, arrow = export.polars_schema(features=features), export.arrow_schema(features=features)
    frames = {
        "csv": pl.read_csv(paths["csv"], schema=schema),
        "ndjson": pl.read_ndjson(paths["ndjson"], schema=schema),
        "parquet": pl.read_parquet(paths["parquet"]).drop("stamp"),  # Parquet's own timestamp column
    }
    tables = {
        "csv": pacsv.read_csv(
            paths["csv"], convert_options=pacsv.ConvertOptions(column_types=arrow, strings_can_be_null=True)
        ),
        "ndjson": pajson.read_json(paths["ndjson"], parse_options=pajson.ParseOptions(explicit_schema=arrow))
        if paths["ndjson"].stat().st_size
        else arrow.empty_table(),
        "parquet": pq.read_table(paths["parquet"]).drop_columns(["stamp"]),
    }
    for fmt in export.FORMATS:
        assert frames[fmt].schema == pl.Schema(schema), fmt
        assert tables[fmt].schema.equals(arrow), fmt
        assert frames[fmt].equals(frames["parquet"]), fmt
        assert tables[fmt].equals(tables["parquet"]), fmt
    df = frames["parquet"]
    assert list(df.columns) == list(export.columns(features))
    if case == "empty":
        assert df.height == 0 and paths["csv"].read_text() == ",".join(export.columns(features)) + "\n"
        assert paths["ndjson"].read_bytes() == b""
        return
    tracks = df.filter(pl.col("kind") == "track")
    assert tracks.height > 1000 and tracks["id"].null_count() == 0
    world = tracks["world_x_m"].is_not_null()
    by_file = {f: bool(world.filter(tracks["file"] == f).any()) for f in map(str, logs)}
    assert by_file == {str(p): p.stem == "patrol" for p in logs}  # odometry only in patrol's rows
    if features:
        feats = df.filter(pl.col("kind") != "track")
        assert feats.height > 1000 and feats["segment"].null_count() == 0 and feats["id"].null_count() == feats.height
        assert set(feats["kind"]) >= {"line", "circle", "leg"}


def test_ground_truth_reads_back_with_its_types(tmp_path):
    import polars as pl
    import pyarrow.parquet as pq

    log = str(SAMPLES / "crowd6.mcap")
    schema = export.polars_schema(export.GROUND_TRUTH_COLUMNS)
    frames = {}
    for fmt in export.FORMATS:
        out = tmp_path / f"gt{SUFFIX[fmt]}"
        assert invoke(log, "--ground-truth", "-o", str(out)).exit_code == 0
        frames[fmt] = (
            {"csv": pl.read_csv, "ndjson": pl.read_ndjson}[fmt](out, schema=schema)
            if fmt != "parquet"
            else pl.read_parquet(out).drop("stamp")
        )
        assert frames[fmt].schema == pl.Schema(schema)
    assert frames["csv"].equals(frames["parquet"]) and frames["ndjson"].equals(frames["parquet"])
    assert pq.read_schema(tmp_path / "gt.parquet").equals(export.parquet_schema(export.GROUND_TRUTH_COLUMNS))


@pytest.mark.parametrize("ground_truth", [False, True])
def test_parquet_stamps_read_as_utc_timestamps_and_carry_their_units(processed, tmp_path, ground_truth):
    """polars reads the Parquet export's `stamp` column, without a schema given, as a UTC timestamp in ns equal to
    `stamp_ns`; the file's metadata holds every column's type and unit."""
    import json

    import polars as pl
    import pyarrow.parquet as pq

    out = tmp_path / "t.parquet"
    source = str(SAMPLES / "crowd6.mcap") if ground_truth else str(processed["patrol"])
    assert invoke(source, *(["--ground-truth"] if ground_truth else []), "-o", str(out)).exit_code == 0
    df = pl.read_parquet(out)
    assert df.schema["stamp"] == pl.Datetime("ns", "UTC") and df.height > 100
    assert df["stamp"].dt.epoch("ns").to_list() == df["stamp_ns"].to_list()
    assert list(df.columns).index("stamp") == list(df.columns).index("stamp_ns") + 1
    schema = pq.read_schema(out)
    described = json.loads(schema.metadata[b"datmo"])["columns"]
    assert list(described) == schema.names
    assert described["stamp"]["type"] == "timestamp[ns, UTC]" and described["stamp_ns"]["type"] == "int64"
    x = "x" if ground_truth else "x_m"
    assert described[x]["unit"] == "m, sensor frame" == schema.field(x).metadata[b"unit"].decode()
