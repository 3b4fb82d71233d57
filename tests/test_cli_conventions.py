"""CLI conventions: --quiet everywhere, piped output never wraps or cuts names, progress bars
with a total, `-o -` refused for logs, ./datmo.toml picked up and `datmo config`, bags as inputs of the
processing commands, shell completion."""

from __future__ import annotations

import contextlib
import json
import os
import pty
import re
import select
import subprocess
import sys
import tomllib
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.cli import COMMANDS, cli
from datmo_cli.commands.options import config_options, param_option
from datmo_cli.logs import mcapio
from datmo_cli.passes.config import BOUNDS, DatmoConfig, load, to_toml
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking.params import TrackingParams

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parents[1]
DATMO = Path(sys.executable).with_name("datmo")
SAMPLE = ROOT / "sample_logs" / "static.mcap"
N_SCANS = 30  # scans of the small logs made here


@contextlib.contextmanager
def inside(folder: Path):
    """Run the block with `folder` as the current folder."""
    here = Path.cwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(here)


def invoke(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    """A simulated hall of N_SCANS scans (5 Hz)."""
    path = tmp_path_factory.mktemp("small") / "hall.mcap"
    result = invoke("simulate", "--duration", N_SCANS / 5, "-o", path)
    assert result.exit_code == 0, result.output
    return path


@pytest.fixture(scope="module")
def tracked(small_log, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tracked") / "hall-tracks.mcap"
    result = invoke("track", small_log, "-o", path)
    assert result.exit_code == 0, result.output
    return path


# ------------------------------------------------------------------------------------ parameter options


def _param_options() -> list[tuple[str, object, list[str]]]:
    """(command, click option, the 'section.key's it sets) of every option built from the configuration."""
    from datmo_cli.commands.options import OPTIONS_KEY

    out = []
    for name in sorted(COMMANDS):
        command = cli.get_command(None, name)
        for p in command.params:
            if getattr(p, "callback", None) is not None and p.callback.__qualname__.startswith("_keep."):
                ctx = click.Context(command)
                p.callback(ctx, p, (1, 2) if p.nargs == 2 else 1)
                out.append((name, p, [f"{s}.{k}" for s, t in ctx.meta[OPTIONS_KEY].items() for k in t]))
    return out


def test_parameter_options_take_their_help_default_and_range_from_the_field():
    options = _param_options()
    assert {name for name, _, _ in options} >= {"segment", "features", "track", "run"}
    defaults = DatmoConfig()
    for name, p, keys in options:
        help_text = p.help
        for key in keys:
            section, _, field_name = key.partition(".")
            value = defaults.get(key)
            assert (f"{value:g}" if isinstance(value, float) else str(value)) in help_text, (name, key, help_text)
            if field_name in BOUNDS[section]:
                assert BOUNDS[section][field_name].describe() in help_text, (name, key)
        if len(keys) == 1:
            assert p.name == keys[0].partition(".")[2], (name, p.opts)


def test_no_command_declares_a_parameter_option_by_hand():
    """An option named after a configuration parameter is built from its field (param_option), in every
    command, so its help, default and range cannot drift from the configuration."""
    from dataclasses import fields

    from datmo_cli.passes.config import SECTIONS

    names = {f.name for section in SECTIONS.values() for f in fields(section)}
    built = {(name, p.name) for name, p, _ in _param_options()}
    for name in sorted(COMMANDS):
        for p in cli.get_command(None, name).params:
            if p.name in names:
                assert (name, p.name) in built, f"datmo {name} {p.opts}: declared by hand, not with param_option"


def test_an_exposed_parameter_option_reaches_the_command_and_the_configuration():
    seen = {}

    @click.command()
    @config_options("a file")
    @param_option("features.leg_model", expose=True)
    def show(cfg, leg_model):
        seen.update(cfg=cfg, leg_model=leg_model)

    assert CliRunner().invoke(show, ["--no-config", "--leg-model", "paper"]).exit_code == 0
    assert (seen["leg_model"], seen["cfg"].features.leg_model) == ("paper", "paper")
    assert CliRunner().invoke(show, ["--no-config"]).exit_code == 0
    assert (seen["leg_model"], seen["cfg"]) == (None, DatmoConfig())


def test_options_override_the_config_file_which_overrides_the_defaults(tmp_path):
    with inside(tmp_path):
        Path("c.toml").write_text("[features]\nc0 = 0.12\nmin_points = 5\n")
        seen = {}

        @click.command()
        @config_options("a file")
        @param_option("features.c0")
        def show(cfg):
            seen["cfg"] = cfg

        assert CliRunner().invoke(show, ["--config", "c.toml", "--c0", "0.2"]).exit_code == 0
        assert (seen["cfg"].features.c0, seen["cfg"].features.min_points) == (0.2, 5)
        assert CliRunner().invoke(show, ["--no-config"]).exit_code == 0
        assert seen["cfg"] == DatmoConfig()


# ------------------------------------------------------------------------------------------------ --quiet


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_takes_quiet(name):
    command = cli.get_command(None, name)
    flags = {o for p in command.params for o in getattr(p, "opts", [])}
    assert {"-q", "--quiet"} <= flags, f"datmo {name} has no -q/--quiet"


def test_quiet_leaves_out_informational_lines_not_the_result(tmp_path, small_log):
    loud = invoke("segment", small_log, "-o", tmp_path / "a.mcap")
    quiet = invoke("segment", small_log, "-o", tmp_path / "b.mcap", "-q")
    assert loud.exit_code == quiet.exit_code == 0
    assert f"segments of {N_SCANS} scans" in loud.stderr
    assert quiet.stderr == ""
    info = invoke("info", small_log, "--json", "--quiet")
    assert info.exit_code == 0 and json.loads(info.stdout)["scan"]["scans"] == N_SCANS


def test_quiet_keeps_warnings_and_errors(tmp_path, small_log):
    out = tmp_path / "exists.mcap"
    out.write_bytes(b"x")
    result = invoke("segment", small_log, "-o", out, "-q")
    assert result.exit_code != 0
    assert result.stderr.startswith("datmo: error: ") and result.stderr.count("\n") == 1


# ------------------------------------------------------------------------------------------ piped output


def test_piped_info_counts_every_datmo_channel(tracked):
    """`datmo info out.mcap | grep -c datmo_msgs` (CliRunner's stdout is not a terminal)."""
    channels = json.loads(invoke("info", tracked, "--json").stdout)["channels"]
    ours = [c["topic"] for c in channels if c["type"].startswith("datmo_msgs/")]
    assert len(ours) >= 4
    out = invoke("info", tracked).stdout
    lines = [line for line in out.splitlines() if "datmo_msgs" in line]
    assert len(lines) == len(ours)
    for topic in ours:
        assert any(topic in line for line in lines), topic  # topic and type whole, on one line


def test_piped_run_table_keeps_the_output_path_whole(tmp_path, small_log):
    deep = tmp_path / ("a-rather-long-folder-name-" * 4) / "out"
    result = invoke("run", small_log, "-o", deep, "--no-report", "-j", "1")
    assert result.exit_code == 0, result.output
    lines = result.stderr.splitlines()
    assert lines[0].split() == ["input", "status", "scans", "scans/s", "tracks", "people", "output", "or", "error"]
    assert str(deep / "hall.mcap") in lines[1]  # the first row of the table, plain (no borders) when piped
    assert all(line == line.rstrip() for line in lines)  # not padded out to the widest row


# ------------------------------------------------------------------------------------------ progress bars


def on_terminal(args: list[str], cwd: Path, timeout: float = 120.0) -> str:
    """What `datmo ARGS` writes to a pseudo-terminal (stdout and stderr are the terminal), without escape codes."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: datmo on the terminal
        os.chdir(cwd)
        os.environ.update(COLUMNS="160", LINES="40", TERM="xterm")
        os.environ.pop("NO_COLOR", None)
        os.execv(str(DATMO), [str(DATMO), *args])
    chunks = []
    while True:
        ready, _, _ = select.select([fd], [], [], timeout)
        if not ready:
            os.kill(pid, 9)
            break
        try:
            data = os.read(fd, 65536)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    os.waitpid(pid, 0)
    return re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", b"".join(chunks).decode("utf-8", "replace"))  # colours, cursor


def test_simulate_draws_a_bar_with_its_total_and_quiet_draws_none(tmp_path):
    shown = on_terminal(["simulate", "--duration", "40", "-o", "a.mcap"], tmp_path)
    assert "simulating" in shown and "/200 scans" in shown
    silent = on_terminal(["simulate", "--duration", "40", "-o", "b.mcap", "-q"], tmp_path)
    assert "simulating" not in silent and "/200" not in silent
    assert (tmp_path / "b.mcap").is_file()


def test_run_bar_counts_each_scan_once(tmp_path, small_log):
    shown = on_terminal(["run", str(small_log), "-o", "out", "--no-report", "-j", "1"], tmp_path)
    assert f"/{N_SCANS} scans" in shown and f"/{2 * N_SCANS} scans" not in shown


def test_record_draws_its_panel_on_a_terminal_and_quiet_draws_none(tmp_path):
    from datmo_cli.lms2xx.emulator import Emulator
    from datmo_cli.passes.simulated import SceneSource

    with Emulator(SceneSource("hall", seed=3, duration=10)) as emu:
        shown = on_terminal(["record", "--port", emu.device_path, "-o", "a.mcap", "--scans", "40"], tmp_path)
        silent = on_terminal(["record", "--port", emu.device_path, "-o", "b.mcap", "--scans", "40", "-q"], tmp_path)
    assert "recording" in shown and "crc errors" in shown
    assert "recording" not in silent and "crc errors" not in silent
    assert mcapio.summary(tmp_path / "b.mcap").topics()[mcapio.TOPIC_SCAN].count == 40


def test_a_panel_is_drawn_only_on_a_terminal_and_not_under_quiet(monkeypatch):
    from rich.text import Text

    from datmo_cli.base import progress

    assert not progress.Panel().shown  # pytest's stderr is not a terminal
    monkeypatch.setattr(progress, "_isatty", lambda stream: True)
    panel = progress.Panel()
    panel.show(Text("first"))
    panel.show(Text("second"))
    assert panel.live is not None and panel.live.is_started
    panel.stop()
    assert not panel.live.is_started
    with click.Context(click.Command("x")) as ctx:
        ctx.meta[progress.QUIET_KEY] = True
        quiet = progress.Panel()
        quiet.show(Text("first"))
        assert not quiet.shown and quiet.live is None


# ------------------------------------------------------------------------------------------------ -o -


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "--duration", "1"],
        ["import", SAMPLE],
        ["segment", SAMPLE],
        ["features", SAMPLE],
        ["track", SAMPLE],
        ["record", "--port", "/dev/null"],
    ],
)
def test_dash_output_is_refused_for_logs(tmp_path, args):
    with inside(tmp_path):
        result = CliRunner().invoke(cli, [*map(str, args), "-o", "-"])
        assert result.exit_code == 1
        assert result.stderr == ("datmo: error: --output -: cannot write an MCAP log to stdout; give a file name\n")
        assert os.listdir(".") == []


def test_dash_is_refused_for_a_model_and_an_output_folder(tmp_path):
    with inside(tmp_path):
        model = CliRunner().invoke(cli, ["train-legs", "--positive", str(SAMPLE), "-o", "-"])
        assert model.exit_code == 1 and "cannot write a model to stdout" in model.stderr
        run = CliRunner().invoke(cli, ["run", str(SAMPLE), "-o", "-"])
        assert run.exit_code == 1 and run.stderr == (
            "datmo: error: --output-dir -: cannot write outputs to stdout; give a folder\n"
        )
        assert os.listdir(".") == []


# ------------------------------------------------------------------------------ ./datmo.toml, datmo config


def _tables(text: str) -> tuple[FeatureParams, TrackingParams]:
    data = tomllib.loads(text)
    return FeatureParams(**data["features"]), TrackingParams(**data["track"])


def test_config_prints_every_key_with_its_source_and_reads_back(tmp_path):
    with inside(tmp_path):
        result = CliRunner().invoke(cli, ["config"])
        assert result.exit_code == 0 and result.stderr == ""
        features, track = _tables(result.stdout)
        assert features == FeatureParams() and track == TrackingParams()
        body = [line for line in result.stdout.splitlines() if " = " in line]
        assert len(body) == len(FeatureParams().to_dict()) + len(TrackingParams().to_dict()) - 1  # d_max once
        assert all(line.split("#", 1)[1].strip().startswith("default") for line in body)
        Path("mine.toml").write_text(result.stdout)
        assert load("mine.toml") == DatmoConfig(features, track)


def test_local_config_is_picked_up_said_and_overridden(tmp_path):
    with inside(tmp_path):
        Path("datmo.toml").write_text("[features]\nc0 = 0.12\n[track]\ngate = 9.5\n")
        Path("other.toml").write_text("[track]\ngate = 7.0\n")
        picked = CliRunner().invoke(cli, ["config"])
        assert picked.exit_code == 0 and picked.stderr == "datmo: using ./datmo.toml\n"
        assert "c0 = 0.12" in picked.stdout and "# from datmo.toml" in picked.stdout
        features, track = _tables(picked.stdout)
        assert (features.c0, track.gate) == (0.12, 9.5) and features.min_points == FeatureParams().min_points
        Path("effective.toml").write_text(picked.stdout)  # read back identically
        again = CliRunner().invoke(cli, ["config", "--config", "effective.toml"])
        assert _tables(again.stdout) == (features, track) and again.stderr == ""
        other = CliRunner().invoke(cli, ["config", "--config", "other.toml"])
        assert _tables(other.stdout) == (FeatureParams(), TrackingParams().replace(gate=7.0))
        none = CliRunner().invoke(cli, ["config", "--no-config"])
        assert _tables(none.stdout) == (FeatureParams(), TrackingParams()) and none.stderr == ""
        quiet = CliRunner().invoke(cli, ["config", "-q"])
        assert quiet.stderr == "" and _tables(quiet.stdout) == (features, track)
        both = CliRunner().invoke(cli, ["config", "--config", "other.toml", "--no-config"])
        assert both.exit_code == 1 and both.stderr.count("\n") == 1 and "--no-config" in both.stderr


def test_config_to_a_file_follows_the_output_rules(tmp_path):
    with inside(tmp_path):
        assert CliRunner().invoke(cli, ["config", "--no-config", "-o", "c.toml"]).exit_code == 0
        assert load("c.toml") == DatmoConfig()
        again = CliRunner().invoke(cli, ["config", "--no-config", "-o", "c.toml"])
        assert again.exit_code == 1 and "exists" in again.stderr


def test_local_config_reaches_the_output_and_its_provenance(tmp_path, small_log):
    with inside(tmp_path):
        Path("datmo.toml").write_text("[features]\nc0 = 0.12\n")
        used = CliRunner().invoke(cli, ["segment", str(small_log), "-o", "a.mcap"])
        assert used.exit_code == 0 and used.stderr.startswith("datmo: using ./datmo.toml\n")
        meta = mcapio.summary("a.mcap").metadata
        assert json.loads(meta["datmo.params"]["features"])["c0"] == 0.12
        assert json.loads(meta["datmo.params"]["config"]) == load("datmo.toml").to_dict()  # the whole tree
        assert meta["datmo"]["command_line"].endswith("--config datmo.toml")
        ignored = CliRunner().invoke(cli, ["segment", str(small_log), "-o", "b.mcap", "--no-config"])
        assert ignored.exit_code == 0 and "datmo.toml" not in ignored.stderr
        meta = mcapio.summary("b.mcap").metadata
        assert json.loads(meta["datmo.params"]["features"])["c0"] == FeatureParams().c0
        assert "--config" not in meta["datmo"]["command_line"]


_FEATURE_KEYS = sorted(k for k, b in BOUNDS["features"].items() if not b.integer)
_TRACK_KEYS = sorted(k for k, b in BOUNDS["track"].items() if not b.integer)


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_toml_of_any_value_reads_back_equal(data):
    """Every float a parameter may take, written by to_toml, reads back to the same float."""
    tables = {}
    for stage, keys in (("features", _FEATURE_KEYS), ("track", _TRACK_KEYS)):
        key = data.draw(st.sampled_from(keys))
        b = BOUNDS[stage][key]
        value = data.draw(st.floats(b.lo, b.hi, exclude_min=b.lo_open, allow_nan=False))
        tables[stage] = {key: value}
    sources = {stage: dict.fromkeys(t, "from a test") for stage, t in tables.items()}
    back = tomllib.loads(to_toml(tables, sources, "a header\nof two lines"))
    tally("config: TOML round trip", failed=back != tables)
    assert back == tables


# ------------------------------------------------------------------------------------------- bag inputs


def _scans(n: int) -> list[tuple[int, bytes]]:
    log = mcapio.read_log(SAMPLE, topics=[mcapio.TOPIC_SCAN])
    stamps, payloads = log.messages[mcapio.TOPIC_SCAN]
    return list(zip(stamps[:n], payloads[:n], strict=True))


def write_ros2_bag(folder: Path, topic: str, storage: str = "sqlite3") -> Path:
    """The first N_SCANS scans of SAMPLE as a ROS 2 bag folder (CDR payloads as they are)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer(folder, version=9, storage_plugin=plugin) as w:
        conn = w.add_connection(topic, "sensor_msgs/msg/LaserScan", typestore=store)
        for stamp, payload in _scans(N_SCANS):
            w.write(conn, int(stamp), payload)
    return folder


def write_ros1_bag(path: Path, topic: str) -> Path:
    """The first N_SCANS scans of SAMPLE as a ROS 1 bag."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ros2 = get_typestore(Stores.ROS2_HUMBLE)
    ros1 = get_typestore(Stores.ROS1_NOETIC)
    scan = "sensor_msgs/msg/LaserScan"
    with Writer(path) as w:
        conn = w.add_connection(topic, scan, typestore=ros1)
        for seq, (stamp, payload) in enumerate(_scans(N_SCANS)):
            m = ros2.deserialize_cdr(payload, scan)
            T = ros1.types
            header = T["std_msgs/msg/Header"](seq=seq, stamp=m.header.stamp, frame_id=m.header.frame_id)
            fields = {
                k: getattr(m, k)
                for k in (
                    "angle_min",
                    "angle_max",
                    "angle_increment",
                    "time_increment",
                    "scan_time",
                    "range_min",
                    "range_max",
                )
            }
            msg = T[scan](
                header=header,
                ranges=np.asarray(m.ranges, np.float32),
                intensities=np.asarray(m.intensities, np.float32),
                **fields,
            )
            w.write(conn, int(stamp), ros1.serialize_ros1(msg, scan))
    return path


def _left_over(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    folder = write_ros2_bag(root / "lab", "/base_scan")
    return {
        "ros1": write_ros1_bag(root / "legs.bag", "/scan"),
        "ros2": folder,
        "db3": next(folder.glob("*.db3")),
        "ros2-mcap": write_ros2_bag(root / "lab2", "/scan", "mcap"),
    }


@pytest.mark.parametrize("kind", ["ros1", "ros2", "db3", "ros2-mcap"])
def test_segment_reads_bags_converted_on_the_fly(tmp_path, bags, kind):
    result = invoke("segment", bags[kind], "-o", tmp_path / "s.mcap")
    assert result.exit_code == 0, result.output
    assert "datmo: converted " in result.stderr and "to a temporary MCAP" in result.stderr
    assert mcapio.summary(tmp_path / "s.mcap").topics()[mcapio.TOPIC_SEGMENTS].count == N_SCANS
    assert _left_over(tmp_path) == []


def test_track_and_features_take_topic_options(tmp_path, bags):
    tracked = invoke("track", bags["ros2"], "--topic", "/base_scan", "-o", tmp_path / "t.mcap", "-q")
    assert tracked.exit_code == 0 and tracked.stderr == ""
    assert mcapio.summary(tmp_path / "t.mcap").topics()[mcapio.TOPIC_TRACKS].count == N_SCANS
    wrong = invoke("features", bags["ros2"], "--topic", "/nope", "-o", tmp_path / "f.mcap")
    assert wrong.exit_code == 1 and wrong.stderr.count("\n") == 1 and "/nope" in wrong.stderr
    assert not (tmp_path / "f.mcap").exists() and _left_over(tmp_path) == []


def test_run_takes_a_ros1_bag_and_names_the_output_after_it(tmp_path, bags):
    out = tmp_path / "out"
    result = invoke("run", bags["ros1"], "-o", out, "--no-report", "-j", "1")
    assert result.exit_code == 0, result.output
    assert "converted" in result.stderr and "legs.bag" in result.stderr
    assert mcapio.summary(out / "legs.mcap").topics()[mcapio.TOPIC_TRACKS].count == N_SCANS
    assert _left_over(out) == []  # the converted copy is gone


# ---------------------------------------------------------------------------------------- completion


@pytest.mark.parametrize("shell", ["bash", "zsh", "fish"])
def test_shell_completion_script(shell):
    env = {**os.environ, "_DATMO_COMPLETE": f"{shell}_source"}
    done = subprocess.run([str(DATMO)], env=env, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0 and "_DATMO_COMPLETE" in done.stdout
    assert ("complete " if shell != "zsh" else "compdef ") in done.stdout


def test_completion_offers_the_commands():
    env = {**os.environ, "_DATMO_COMPLETE": "bash_complete", "COMP_WORDS": "datmo con", "COMP_CWORD": "1"}
    done = subprocess.run([str(DATMO)], env=env, capture_output=True, text=True, timeout=60, check=False)
    assert "plain,config" in done.stdout.splitlines()
