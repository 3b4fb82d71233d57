"""`datmo run` against the stages: its one-pass output holds, channel by channel, the same message payloads
as `datmo segment`, `datmo features` and `datmo track` run one after another through files."""

from __future__ import annotations

import importlib.util

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio

pytestmark = [
    pytest.mark.cli,
    pytest.mark.skipif(
        importlib.util.find_spec("datmo_cli.perception.features") is None,
        reason="datmo_cli.perception.features (datmo segment, datmo features) is not built yet",
    ),
]


def invoke(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, (args, result.output)
    return result


def payloads(path):
    log = mcapio.read_log(path, topics=None)
    return {topic: (list(stamps), list(data)) for topic, (stamps, data) in log.messages.items() if data}


@pytest.fixture(scope="module", params=["hall", "patrol"])
def simulated(request, tmp_path_factory):
    """10 s of a simulated scene: hall (still scanner), patrol (moving scanner, with /odom)."""
    path = tmp_path_factory.mktemp("run") / f"{request.param}.mcap"
    invoke("simulate", "--scene", request.param, "--duration", "10", "-o", path)
    return path


def test_one_pass_equals_the_stages_one_by_one(tmp_path, simulated):
    seg, feat, track = tmp_path / "seg.mcap", tmp_path / "feat.mcap", tmp_path / "track.mcap"
    invoke("segment", simulated, "-o", seg)
    invoke("features", seg, "-o", feat)
    invoke("track", feat, "-o", track)
    invoke("run", simulated, "-o", tmp_path / "run", "--no-report", "--jobs", "1")
    staged, one_pass = payloads(track), payloads(tmp_path / "run" / simulated.name)
    assert sorted(one_pass) == sorted(staged)
    for topic in (mcapio.TOPIC_SEGMENTS, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS, mcapio.TOPIC_TRACKS):
        assert topic in one_pass, topic
    for topic, (stamps, data) in staged.items():
        assert one_pass[topic][0] == stamps, topic
        assert one_pass[topic][1] == data, topic


def test_run_output_reports_and_evaluates(tmp_path, simulated):
    out = tmp_path / "out"
    result = invoke("run", simulated, "-o", out, "--format", "json", "--jobs", "1")
    assert '"tracks"' in result.stdout
    meta = mcapio.summary(out / simulated.name).metadata
    assert meta["datmo"]["command"] == "run" and str(simulated) in meta["datmo.inputs"]
    ev = CliRunner().invoke(cli, ["evaluate", str(out / simulated.name), "--format", "json"])
    assert ev.exit_code == 0, ev.output
