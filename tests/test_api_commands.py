"""Every `datmo` command's work is a call of datmo_cli.api (docs/python.md, "Every command from Python"): each
command of cli.COMMANDS has its call named in that table, and the calls of import, simulate, info, config,
export, emulate, play, node and train-legs do what their commands do (the same files, the same lines said,
what `datmo info --json` prints)."""

from __future__ import annotations

import json
import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli import api
from datmo_cli.base.bounds import OptionError
from datmo_cli.base.errors import ConfigError, InputError
from datmo_cli.cli import COMMANDS, cli
from datmo_cli.logs import mcapio

pytestmark = [pytest.mark.cli, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_logs"
# the commands whose work moved into the pipeline layer: their modules call datmo_cli.api
THIN = ("import", "info", "simulate", "emulate", "export", "play", "node", "train-legs", "config")


def datmo(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def table_rows() -> dict[str, str]:
    """{command: its `from Python` cell} of docs/python.md's table "Every command from Python"."""
    text = (ROOT / "docs" / "python.md").read_text(encoding="utf-8")
    body = text.split("## Every command from Python\n", 1)[1].split("\n## ", 1)[0]
    rows: dict[str, str] = {}
    for first, second in re.findall(r"^\| (`datmo [^|]+) \| (.+) \|$", body, re.M):
        for name in re.findall(r"`(?:datmo )?([\w-]+)`", first):
            rows[name] = second
    return rows


def test_every_command_has_its_api_call_in_the_table():
    """A command added to cli.COMMANDS without a call of datmo_cli.api named in docs/python.md's table fails."""
    rows = table_rows()
    assert sorted(set(COMMANDS) - set(rows)) == []
    for command, cell in rows.items():
        names = re.findall(r"`api\.(\w+)", cell)
        assert names, f"datmo {command}: the table names no api call"
        for name in names:
            assert name in api.__all__, f"datmo {command}: api.{name} is not in api.__all__"
            assert callable(getattr(api, name)), name


def test_every_exported_name_resolves():
    for name in api.__all__:
        assert getattr(api, name) is not None, name


@pytest.mark.parametrize("command", THIN)
def test_the_command_calls_the_api(command):
    source = (ROOT / "datmo_cli" / "commands" / f"{COMMANDS[command][0]}.py").read_text(encoding="utf-8")
    assert "from .. import api" in source


def _scans_equal(a: Path, b: Path) -> None:
    ra, rb = mcapio.read_run(a), mcapio.read_run(b)
    assert np.array_equal(ra.stamps, rb.stamps)
    assert np.array_equal(ra.ranges, rb.ranges)
    assert ra.geometry == rb.geometry


def test_import_log_writes_and_says_what_datmo_import_does(tmp_path):
    src = SAMPLES / "csail-excerpt.mcap"
    code, _, err = datmo("import", src, "-o", tmp_path / "cli.mcap", "--max-scans", 40)
    assert code == 0, err
    result = api.import_log(src, tmp_path / "api.mcap", max_scans=40)
    assert isinstance(result, api.ImportResult) and result.scans == 40
    assert err.strip().splitlines()[-1] == result.summary.replace("api.mcap", "cli.mcap")
    _scans_equal(tmp_path / "cli.mcap", tmp_path / "api.mcap")
    meta = mcapio.read_log(tmp_path / "api.mcap").metadata
    assert any("datmo_cli.api.import_log" in v for record in meta.values() for v in record.values())
    with pytest.raises(InputError):
        api.import_log(tmp_path / "missing.log", tmp_path / "x.mcap")


def test_simulate_writes_a_log_with_ground_truth_as_datmo_simulate_does(tmp_path):
    code, _, err = datmo("simulate", "--scene", "hall", "--duration", 2, "-o", tmp_path / "cli.mcap")
    assert code == 0, err
    result = api.simulate(tmp_path / "api.mcap", "hall", duration=2)
    assert isinstance(result, api.SimulateResult) and not result.bag
    assert err.strip().splitlines()[-1] == result.summary.replace("api.mcap", "cli.mcap")
    _scans_equal(tmp_path / "cli.mcap", tmp_path / "api.mcap")
    truth = api.open_log(tmp_path / "api.mcap").contents.topics()[mcapio.TOPIC_GROUND_TRUTH]
    assert truth.count == result.scans > 0 and result.objects > 0


def test_simulate_refuses_lms_settings_for_a_scene_with_its_own_scanner(tmp_path):
    with pytest.raises(OptionError, match=r"sets its own scanner \(\[scanner\]\); --angle applies to the LMS200"):
        api.simulate(tmp_path / "x.mcap", "lab-drive", angle=180)
    assert not (tmp_path / "x.mcap").exists()


def test_info_returns_what_datmo_info_json_prints(tmp_path):
    code, out, err = datmo("info", SAMPLES / "hall.mcap", "--json")
    assert code == 0, err
    assert json.loads(json.dumps(api.info(SAMPLES / "hall.mcap"))) == json.loads(out)
    no_scans = tmp_path / "empty.mcap"
    with mcapio.LogWriter(no_scans):
        pass
    with pytest.warns(UserWarning, match="no scans on /scan"):
        assert api.info(no_scans)["scan"] is None


def test_config_returns_what_datmo_config_prints(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./datmo.toml
    code, out, err = datmo("config", "--no-config")
    assert code == 0, err
    assert api.config() == out
    given = tmp_path / "given.toml"
    given.write_text("[track]\ngate = 9.0\n")
    code, out, err = datmo("config", "--config", given)
    assert code == 0, err
    text = api.config(given, tmp_path / "back.toml")
    assert text == out and "gate = 9.0" in text and f"from {given}" in text
    assert (tmp_path / "back.toml").read_text() == text
    assert api.config({"track": {"gate": 9.0}}).count("gate = 9.0") == 1


@pytest.fixture(scope="module")
def tracked(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("tracked") / "static-tracks.mcap"
    api.process(SAMPLES / "static.mcap", out)
    return out


@pytest.mark.slow
def test_export_writes_and_says_what_datmo_export_does(tracked, tmp_path):
    code, _, err = datmo("export", tracked, "-o", tmp_path / "cli.csv", "--features")
    assert code == 0, err
    result = api.export([tracked], tmp_path / "api.csv", features=True)
    assert isinstance(result, api.ExportResult) and result.rows > 0 and result.fmt == "csv"
    assert (tmp_path / "api.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    assert err.strip().splitlines()[-1] == result.summary.replace("api.csv", "cli.csv")
    with pytest.raises(ConfigError, match="--include-occluded: only with --ground-truth"):
        api.export([tracked], tmp_path / "x.csv", include_occluded=True)


def test_export_of_ground_truth_is_the_commands(tmp_path):
    sim = api.simulate(tmp_path / "sim.mcap", "crowd", duration=2, seed=1).output
    code, _, err = datmo("export", sim, "--ground-truth", "-o", tmp_path / "cli.csv")
    assert code == 0, err
    result = api.export([sim], tmp_path / "api.csv", ground_truth=True)
    assert (tmp_path / "api.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    assert err.strip().splitlines()[-1] == result.summary.replace("api.csv", "cli.csv")


def test_emulate_serves_an_lms200_that_records_and_removes_its_link(tmp_path):
    link = tmp_path / "lms"
    stop = threading.Event()
    with api.emulate(log=SAMPLES / "hall.mcap", link=link) as lms:
        assert isinstance(lms, api.Emulation) and os.readlink(link) == lms.device_path
        recorded = api.record(lms.device_path, tmp_path / "rec.mcap", baud=500000, max_scans=5)
        stop.set()
        assert lms.serve(stop) is True  # stopped, not disconnected
    assert recorded.scans == 5 and api.open_log(tmp_path / "rec.mcap").scans == 5
    assert not os.path.lexists(link) and lms.report.startswith("sent ")
    with pytest.raises(ConfigError, match="give --scene or --log, not both"):
        api.emulate("hall", SAMPLES / "hall.mcap")


def test_play_serves_every_scan_of_a_log():
    pytest.importorskip("foxglove")
    with api.Player(SAMPLES / "static.mcap", port=0, rate=100.0) as player:
        assert player.url.startswith("ws://") and not player.processed
        assert player.run() == player.scans == 300
        assert player.sent > 0


def test_node_starts_spins_until_stopped_and_says_what_it_did(monkeypatch):
    from datmo_cli.ros2 import node as ros_node

    stop = threading.Event()

    class FakeNode:
        """ros2.node.Node's face: the topics, the feed, spin, log, close, summary."""

        def __init__(self, domain, scan_topic, odom_topic, cfg, say, **graph) -> None:
            self.scan_topic, self.odom_topic, self.topics = scan_topic, odom_topic, {"/datmo/tracks": "t"}
            self.feed = type("Feed", (), {"failure": None})()
            self.name, self.say, self.logged, self.spins, self.closed = "/datmo", say, [], 0, False

        def spin(self) -> None:
            self.spins += 1
            self.say(f"datmo node: the scans' geometry changed ({self.spins} beams): tracking starts over")
            if self.spins == 20:
                stop.set()

        def log(self, level: int, line: str) -> None:
            self.logged.append((level, line))

        def close(self) -> None:
            self.closed = True

        def summary(self) -> str:
            return "20 scans received"

    monkeypatch.setattr(ros_node, "Node", FakeNode)
    monkeypatch.setattr("datmo_cli.ros2.dds.domain_id", lambda value=None: 7 if value is None else value)
    warned: list[str] = []
    live = api.node("/front/scan", "/odom", on_warning=warned.append)
    assert isinstance(live, api.LiveNode)
    assert live.started == "datmo node: ROS 2 domain 7: /front/scan and /odom in, /datmo/tracks out"
    live.spin(stop)
    assert live.node.spins == 20 and len(warned) < 20  # rate-limited
    assert live.close("done") == "datmo node: stopped (done); 20 scans received" and live.node.closed
    assert live.node.logged[0] == (20, f"{live.started}; node /datmo")


@pytest.mark.slow
def test_train_legs_trains_and_writes_a_model(tmp_path):
    pytest.importorskip("sklearn")
    from datmo_cli.perception.leg_model import LegModel
    from tests.synthetic_legs import scene, write_bag

    positive = write_bag(tmp_path / "p.bag", *scene(12, seed=0))
    out = tmp_path / "legs.npz"
    seen = []
    trained = api.train_legs([positive], [], out, on_trained=lambda r: seen.append(out.exists()))
    assert isinstance(trained, api.LegTraining) and seen == [False]  # told before the model is written
    assert trained.result.held_out == [] and LegModel.load(out).threshold_p == pytest.approx(trained.result.threshold)
    assert trained.summary.startswith(f"{out}: {trained.result.model.n_trees} trees")
    with pytest.raises(InputError, match="given as --negative and as --positive"):
        api.train_legs([positive], [positive], tmp_path / "other.npz")
