"""`datmo evaluate`: CLEAR-MOT figures of a hand-made log with known answers, CSV ground truth, CI threshold."""

from __future__ import annotations

import json

import numpy as np
import pytest
import synthetic_logs as syn
from click.testing import CliRunner

from datmo_cli import evaluate as ev
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, types

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("evaluate") / "run.mcap"
    syn.write(path)
    return path


def frames(**kw):
    gt = [syn.truth(k) for k in range(syn.N)]
    tr = [syn.tracks(k) for k in range(syn.N)]

    def off(parts):
        return np.concatenate([[0], np.cumsum([len(p) for p in parts])])

    gt, regions, hyps = ev.frames_from_channels(
        syn.STAMPS, off(gt), np.concatenate(gt), None, syn.STAMPS, off(tr), np.concatenate(tr), **kw
    )
    return gt, hyps, regions


def score(match_radius=0.5, **kw):
    gt, hyps, regions = frames(**kw)
    return ev.evaluate(gt, hyps, regions=regions, match_radius=match_radius)


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_known_figures():
    a = score()["all"]
    e = syn.EXPECTED
    assert a["num_objects"] == e["objects"] and a["num_misses"] == e["misses"]
    assert a["num_false_positives"] == e["false_positives"] and a["num_switches"] == e["switches"]
    assert a["num_matches"] + a["num_switches"] == e["matches"]  # motmetrics counts a switch apart
    assert a["mota"] == pytest.approx(e["mota"])
    assert a["motp"] == pytest.approx(e["motp"], abs=1e-6)
    assert a["num_unique_objects"] == 3  # the column is not a mover
    assert a["ignored_hypotheses"] == e["ignored"]  # the static track on the column


def test_per_class_figures():
    s = score()
    assert s["person"]["num_objects"] == 95 and s["person"]["num_switches"] == 1
    assert s["person"]["mota"] == pytest.approx(1 - 3 / 95)
    assert s["circle object"]["mota"] == pytest.approx(0.8) and s["circle object"]["num_misses"] == 10
    rect = s["rectangular object"]  # only the false track has this class
    assert rect["num_false_positives"] == 10 and rect["num_objects"] == 0 and rect["mota"] is None


def test_include_occluded_scores_hidden_movers_with_coasting_tracks():
    s = score(include_occluded=True)["all"]
    assert s["num_objects"] == 150 and s["num_misses"] == 12 and s["num_switches"] == 1
    assert s["mota"] == pytest.approx(1 - 23 / 150)


def test_static_tracks_elsewhere_count_and_exclude_static_drops_them():
    gt, hyps, _ = frames()
    assert ev.evaluate(gt, hyps)["all"]["num_false_positives"] == 10 + 50  # no regions: the column track is false
    assert score(exclude_static=True)["all"]["ignored_hypotheses"] == 0


def test_dont_care_regions():
    objs = np.zeros(4, cdr.element_dtype(types.GROUND_TRUTH_OBJECT))
    objs["id"] = [1, 2, 3, 4]
    objs["classification"] = [1, 3, 7, 1]  # walking person, parked box, wall, person hidden
    objs["moving"] = [1, 0, 0, 1]
    objs["visible"] = [1, 1, 1, 0]
    objs["x"], objs["y"] = [2.0, 4.0, 6.0, 3.0], [0.0, 2.0, 0.0, -2.0]
    objs["orientation"] = [0, 0, np.pi / 2, 0]  # the wall runs along y through (6, 0), 4 m long
    objs["length"], objs["width"] = [0.5, 0.8, 4.0, 0.5], [0.5, 0.4, 0.0, 0.5]
    gt, regions = ev.ground_truth_frames(np.array([0]), np.array([0, 4]), objs)
    assert gt.ids.tolist() == [1]
    px = np.array([2.1, 4.6, 6.3, 6.3, 3.0, 6.0])
    py = np.array([0.0, 2.0, 1.9, 2.6, -2.2, -5.0])
    assert regions.near(0, px, py, 0.5).tolist() == [False, True, True, False, True, False]
    hyps = ev.Frames(np.array([0]), np.array([0, 6]), np.arange(10, 16), px, py, np.zeros(6, np.int64))
    s = ev.evaluate(gt, hyps, regions=regions)["all"]
    assert (s["num_matches"], s["ignored_hypotheses"], s["num_false_positives"]) == (1, 3, 2)


def test_match_radius():
    assert score(match_radius=0.049)["all"]["num_matches"] == 0
    with pytest.raises(ValueError):
        score(match_radius=0)


def test_select_keeps_empty_frames():
    f = ev.Frames(
        np.array([1, 2, 3, 4]),
        np.array([0, 0, 2, 2, 3]),
        np.array([1, 2, 3]),
        np.zeros(3),
        np.zeros(3),
        np.array([1, 5, 1]),
    )
    g = f.select(f.cls == 1)
    assert g.offsets.tolist() == [0, 0, 1, 1, 2] and g.ids.tolist() == [1, 3]


def test_align_nearest_within_tolerance():
    gt = ev.Frames(np.array([100, 205, 390]), np.zeros(4, np.int64), *([np.zeros(0)] * 4))
    hy = ev.Frames(np.array([300, 200, 400]), np.zeros(4, np.int64), *([np.zeros(0)] * 4))
    assert ev.align(gt, hy, 10).tolist() == [-1, 1, 2]


def gt_csv_text(round_to_ms: bool = False) -> str:
    lines = ["stamp_ns,id,x,y,class"]
    names = {1: "person", 2: "circle"}
    for k in range(syn.N):
        stamp = int(syn.STAMPS[k]) // 1_000_000 * 1_000_000 + (300_000 if round_to_ms else 0)
        for o in syn.truth(k):
            if o["classification"] in names and o["visible"]:
                lines.append(f"{stamp},{o['id']},{o['x']:.4f},{o['y']:.4f},{names[int(o['classification'])]}")
    return "\n".join(lines) + "\n"


def test_csv_ground_truth_gives_the_channel_figures(tmp_path, log):
    path = tmp_path / "gt.csv"
    path.write_text(gt_csv_text(round_to_ms=True))
    # CSV has no don't-care regions: without --exclude-static the static track on the column is false
    assert (
        json.loads(invoke("evaluate", log, "--gt", path, "--format", "json").output)["scores"]["all"][
            "num_false_positives"
        ]
        == 60
    )
    from_csv = json.loads(invoke("evaluate", log, "--gt", path, "--format", "json", "--exclude-static").output)
    from_channel = json.loads(invoke("evaluate", log, "--format", "json").output)
    assert from_csv["ground_truth"] == str(path) and from_channel["ground_truth"] == "/datmo/ground_truth"
    for key in ("num_objects", "num_matches", "num_misses", "num_false_positives", "num_switches"):
        assert from_csv["scores"]["all"][key] == from_channel["scores"]["all"][key], key
    assert from_csv["scores"]["person"]["num_objects"] == 95


def test_csv_empty_id_marks_an_annotated_scan_with_nothing():
    f = ev.parse_ground_truth_csv("stamp_ns,id,x,y\n10,,,\n20,1,1.0,2.0\n")
    assert f.stamps.tolist() == [10, 20] and f.offsets.tolist() == [0, 0, 1] and f.cls.tolist() == [0]


@pytest.mark.parametrize(
    "text, message",
    [
        ("stamp,id,x,y\n1,1,0,0\n", "missing stamp_ns"),
        ("stamp_ns,id,x,y\n1,1,zero,0\n", "line 2"),
        ("stamp_ns,id,x,y\n", "no ground-truth rows"),
    ],
)
def test_csv_errors(tmp_path, log, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    result = invoke("evaluate", log, "--gt", path)
    assert result.exit_code == 1 and message in result.output and result.output.startswith("datmo: error: ")


def test_cli_tables_and_json(log):
    result = invoke("evaluate", log)
    assert result.exit_code == 0, result.output
    for text in ("MOTA", "IDF1", "person", "circle object", "0.841"):
        assert text in result.output
    data = json.loads(invoke("evaluate", log, "--format", "json").output)
    assert data["scores"]["all"]["mota"] == pytest.approx(syn.EXPECTED["mota"])
    assert data["match_radius_m"] == 0.5
    assert "| all | 0.841 | 0.050 |" in invoke("evaluate", log, "--format", "markdown").output


def test_min_mota_gates_ci(log):
    ok = invoke("evaluate", log, "--min-mota", "0.8", "--format", "json")
    assert ok.exit_code == 0
    low = invoke("evaluate", log, "--min-mota", "0.9", "--format", "json")
    assert low.exit_code == 1
    assert low.output.endswith(f"datmo: error: {log}: MOTA 0.841 is below --min-mota 0.9\n")
    assert json.loads(low.output[: low.output.rindex("}") + 1])["scores"]["all"]["num_switches"] == 1


def test_cli_text_csv_and_json_carry_hota(log):
    import csv
    import io

    data = json.loads(invoke("evaluate", log, "--format", "json").output)["scores"]
    assert set(data) == {"all", "person", "circle object", "rectangular object"}
    assert 0 < data["all"]["hota"] < 1 and 0 < data["all"]["assa"] < 1 and 0 < data["all"]["loca"] <= 1
    assert data["rectangular object"]["hota"] == 0.0  # only a false track has this class
    result = invoke("evaluate", log, "--format", "csv")
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [r["class"] for r in rows] == list(data)
    assert list(rows[0]) == ["class"] + list(data["all"])  # the JSON's keys, in order
    for r in rows:
        for key in ("hota", "deta", "assa", "mota", "num_switches"):
            v = data[r["class"]][key]
            assert r[key] == ("" if v is None else str(v)), (r["class"], key)
    text = invoke("evaluate", log).output
    for label in ("HOTA", "DetA", "AssA", "LocA"):
        assert label in text
    assert f"{data['all']['hota']:.3f}" in text
    markdown = invoke("evaluate", log, "--format", "markdown").output
    assert "| IDF1 | HOTA | DetA | AssA | LocA |" in markdown


def test_min_hota_gates_ci(log):
    hota = json.loads(invoke("evaluate", log, "--format", "json").output)["scores"]["all"]["hota"]
    assert invoke("evaluate", log, "--format", "csv", "--min-hota", f"{hota - 0.01:.4f}").exit_code == 0
    low = invoke("evaluate", log, "--format", "csv", "--min-hota", f"{hota + 0.01:.4f}")
    assert low.exit_code == 1 and "Traceback" not in low.output
    assert low.output.endswith(f"datmo: error: {log}: HOTA {hota:.3f} is below --min-hota {hota + 0.01:.4f}\n")
    both = invoke("evaluate", log, "--format", "csv", "--min-hota", "0.99", "--min-mota", "0.9")
    assert both.output.endswith(f"MOTA 0.841 is below --min-mota 0.9; HOTA {hota:.3f} is below --min-hota 0.99\n")
    for bad in ("1.5", "-0.1", "nan"):
        result = invoke("evaluate", log, "--min-hota", bad)
        assert result.exit_code == 2 and "--min-hota" in result.output, bad


def test_progress_counts_ground_truth_frames():
    calls = []
    gt, hyps, regions = frames()
    ev.evaluate(gt, hyps, regions=regions, progress=lambda done, total, stage: calls.append((done, total, stage)))
    assert {total for _, total, _ in calls} == {syn.N}
    matching = [done for done, _, stage in calls if stage == "matching"]
    assert matching == sorted(matching) and matching[-1] == syn.N
    hota_stages = [stage for done, _, stage in calls if stage.startswith("HOTA") and done == syn.N]
    assert hota_stages == ["HOTA all", "HOTA person", "HOTA circle object", "HOTA rectangular object"]


def test_quiet_prints_only_the_result(log):
    result = CliRunner().invoke(cli, ["evaluate", str(log), "--format", "json", "--quiet"])
    assert result.exit_code == 0 and json.loads(result.output)["scores"]["all"]["num_switches"] == 1


@pytest.mark.parametrize(
    "channels, needle",
    [
        ({"with_tracks": False}, "no messages on /datmo/tracks; run datmo track (or datmo run) first"),
        (
            {"with_truth": False},
            "no messages on /datmo/ground_truth; run datmo simulate first, or give annotations with --gt",
        ),
    ],
)
def test_missing_channels_name_the_command(tmp_path, channels, needle):
    path = tmp_path / "partial.mcap"
    syn.write(path, **channels)
    result = invoke("evaluate", path)
    assert result.exit_code == 1 and needle in result.output and "Traceback" not in result.output


def oracle_tracks(log):
    """Tracks equal to the ground truth's visible movers, all confirmed: a perfect tracker."""
    from datmo_cli.report import decode_channel

    truth = decode_channel(types.GROUND_TRUTH, log.messages["/datmo/ground_truth"][1])
    objs, off = truth.items["objects"], truth.offsets["objects"]
    out = []
    for k in range(len(truth)):
        o = objs[off[k] : off[k + 1]]
        o = o[np.isin(o["classification"], [1, 2, 3]) & (o["visible"] == 1)]
        t = np.zeros(len(o), cdr.element_dtype(types.TRACK))
        for f in ("id", "x", "y", "vx", "vy"):
            t[f] = o[f]
        t["classification"], t["status"], t["mobility"] = o["classification"], 1, o["moving"]
        out.append(t)
    return truth, out


@pytest.mark.parametrize("name", ["hall", "patrol", "corridor"])
def test_a_perfect_tracker_scores_perfectly_on_the_sample_logs(sample_logs, name):
    from datmo_cli.logs import mcapio

    path = sample_logs / f"{name}.mcap"
    if not path.exists():
        pytest.skip(f"{path} not generated")
    truth, tracks = oracle_tracks(mcapio.read_log(path, topics=["/datmo/ground_truth"]))
    off = np.concatenate([[0], np.cumsum([len(t) for t in tracks])])
    gt, regions, hyps = ev.frames_from_channels(
        truth.stamps,
        truth.offsets["objects"],
        truth.items["objects"],
        truth.scalars["sensor_theta"],
        truth.stamps,
        off,
        np.concatenate(tracks),
    )
    s = ev.evaluate(gt, hyps, regions=regions)["all"]
    assert s["num_objects"] > 100
    assert (s["mota"], s["idf1"], s["num_false_positives"], s["num_switches"]) == (1.0, 1.0, 0, 0)
    assert (s["hota"], s["deta"], s["assa"], s["loca"]) == pytest.approx((1.0, 1.0, 1.0, 1.0), abs=1e-12)
    # people who never move (corridor, patrol: one stands all along) are ignored, not false positives
    assert (s["ignored_hypotheses"] > 0) == (name != "hall")
