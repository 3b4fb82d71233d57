"""`datmo segment` and `datmo features` end to end: channels, parameters in the metadata, config files,
options, markers that ROS tools decode, and the reliability rules (no overwrite, input untouched)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.passes.feature_channels import decode_segments
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def hall(tmp_path_factory):
    src = tmp_path_factory.mktemp("hall") / "hall.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "hall", "--duration", "10", "-o", str(src)])
    assert result.exit_code == 0, result.output
    return src


def invoke(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


def params_of(path) -> dict:
    meta = mcapio.summary(path).metadata
    return json.loads(meta["datmo.params"]["features"])


def test_segment_writes_one_message_per_scan_with_its_parameters(tmp_path, hall):
    out = tmp_path / "seg.mcap"
    result = invoke("segment", hall, "-o", out, "--c0", "0.12", "--min-points", "3")
    assert result.exit_code == 0, result.output
    log = mcapio.read_log(out, topics=None)
    run = mcapio.run_from_log(log)
    stamps, payloads = log.messages[mcapio.TOPIC_SEGMENTS]
    assert len(payloads) == len(run) == 50 and list(stamps) == list(run.stamps)
    start, end, offsets = decode_segments(payloads)
    assert np.all(end - start >= 3) and offsets[-1] == len(start) > 0
    p = params_of(out)
    assert p["c0"] == 0.12 and p["min_points"] == 3
    assert mcapio.summary(out).metadata["datmo"]["command"] == "segment"


def test_features_writes_features_landmarks_markers_and_segments(tmp_path, hall):
    lean = tmp_path / "lean.mcap"
    assert invoke("features", hall, "-o", lean).exit_code == 0
    assert not mcapio.read_log(lean, topics=None).has(mcapio.TOPIC_MARKERS_FEATURES)  # markers only when asked
    out = tmp_path / "feat.mcap"
    result = invoke("features", hall, "-o", out, "--markers")
    assert result.exit_code == 0, result.output
    assert "landmarks" in result.stderr
    log = mcapio.read_log(out, topics=None)
    n = len(mcapio.run_from_log(log))
    for topic in (
        mcapio.TOPIC_SEGMENTS,
        mcapio.TOPIC_FEATURES,
        mcapio.TOPIC_LANDMARKS,
        mcapio.TOPIC_MARKERS_FEATURES,
        mcapio.TOPIC_GROUND_TRUTH,
    ):
        assert len(log.messages[topic][1]) == n, topic
    feats = [cdr.decode(types.FEATURES, p) for p in log.messages[mcapio.TOPIC_FEATURES][1]]
    assert sum(len(f["lines"]) for f in feats) > n  # walls in every scan
    assert sum(len(f["circles"]) for f in feats) > n  # two columns in view
    last = cdr.decode(types.LANDMARKS, log.messages[mcapio.TOPIC_LANDMARKS][1][-1])
    assert len(last["landmarks"]) >= 2 and last["frame_id"] == "laser"
    store = types.typestore()
    for payload in log.messages[mcapio.TOPIC_MARKERS_FEATURES][1][::10]:
        msg = store.deserialize_cdr(payload, types.MARKER_ARRAY)
        assert [m.id for m in msg.markers] == [0, 1, 2, 3, 4]
        assert len(msg.markers[1].points) % 2 == 0
    assert params_of(out) == FeatureParams().to_dict()


def test_features_on_a_segmented_log_equals_features_on_the_raw_log(tmp_path, hall):
    seg, a, b = tmp_path / "seg.mcap", tmp_path / "a.mcap", tmp_path / "b.mcap"
    assert invoke("segment", hall, "-o", seg).exit_code == 0
    assert invoke("features", seg, "-o", a).exit_code == 0
    assert invoke("features", hall, "-o", b).exit_code == 0
    ma = mcapio.read_log(a, topics=None).messages
    mb = mcapio.read_log(b, topics=None).messages
    assert sorted(ma) == sorted(mb)
    for topic in ma:
        assert ma[topic] == mb[topic], topic


def test_config_file_then_options_override_the_defaults(tmp_path, hall):
    config = tmp_path / "datmo.toml"
    config.write_text("[features]\nrho_resolution = 0.05\nmin_points = 4\n\n[track]\ngate = 9.0\n")
    out = tmp_path / "feat.mcap"
    result = invoke("features", hall, "-o", out, "--config", config, "--min-points", "6")
    assert result.exit_code == 0, result.output
    p = params_of(out)
    assert p["rho_resolution"] == 0.05 and p["min_points"] == 6 and p["c0"] == FeatureParams().c0


@pytest.mark.parametrize(
    "text, names",
    [
        ("[features]\nrho_resoluton = 0.05\n", "features.rho_resoluton: unknown parameter"),
        ("[features]\nmin_points = 0\n", "features.min_points"),
        ("[features]\nc0 = 'wide'\n", "features.c0"),
        ("[features\n", "datmo.toml"),
    ],
)
def test_a_bad_config_is_one_line_naming_the_key(tmp_path, hall, text, names):
    config = tmp_path / "datmo.toml"
    config.write_text(text)
    result = invoke("features", hall, "-o", tmp_path / "x.mcap", "--config", config)
    assert result.exit_code != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error:") and names in lines[0]
    assert not (tmp_path / "x.mcap").exists()


def test_existing_output_is_kept_and_input_untouched(tmp_path, hall):
    before = hashlib.sha256(hall.read_bytes()).hexdigest()
    out = tmp_path / "feat.mcap"
    out.write_bytes(b"precious")
    for command in ("segment", "features"):
        result = invoke(command, hall, "-o", out)
        assert result.exit_code != 0 and "--force" in result.stderr
        assert out.read_bytes() == b"precious"
    assert invoke("features", hall, "-o", out, "--force").exit_code == 0
    assert mcapio.summary(out).metadata["datmo"]["command"] == "features"
    assert hashlib.sha256(hall.read_bytes()).hexdigest() == before
    assert [p.name for p in tmp_path.iterdir()] == ["feat.mcap"]  # no temporary file left behind


def test_a_log_without_scans_is_a_clear_error(tmp_path):
    empty = tmp_path / "empty.mcap"
    with mcapio.LogWriter(empty) as w:
        w.add_metadata("note", {"what": "nothing"})
    result = invoke("features", empty, "-o", tmp_path / "x.mcap")
    assert result.exit_code != 0
    assert result.stderr.startswith("datmo: error:") and "/scan" in result.stderr


def test_landmarks_are_in_the_odom_frame_when_the_log_has_odometry(tmp_path):
    src = tmp_path / "patrol.mcap"
    assert invoke("simulate", "--scene", "patrol", "--duration", "20", "-o", src).exit_code == 0
    run, odom = mcapio.read_run(src), mcapio.read_odometry(src)
    f = extract_run(run, odometry=odom)
    assert f.landmark_frame == odom.frame_id
    out = tmp_path / "feat.mcap"
    assert invoke("features", src, "-o", out).exit_code == 0
    last = cdr.decode(types.LANDMARKS, mcapio.read_messages(out, mcapio.TOPIC_LANDMARKS)[1][-1])
    assert last["frame_id"] == odom.frame_id
