"""The third round's exit-70s, traceback and misleading messages (issue #33): each case gives one line that
names the file and the real problem, with the right exit status, and nothing after it."""

from __future__ import annotations

import subprocess
import sys

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli


def run_cli(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result.exit_code, result.stdout, result.stderr


def one_error(err: str) -> str:
    """The one line of an error on stderr (asserted: one line, datmo's prefix, no traceback)."""
    assert err.count("\n") == 1 and err.startswith("datmo: error: ") and "Traceback" not in err, err[:2000]
    assert "internal error" not in err, err
    return err.strip()


# ------------------------------------------------------------------------------------------- exit 70


def test_a_whole_number_of_5000_digits_in_a_config_is_a_config_error(tmp_path):
    cfg = tmp_path / "big.toml"
    cfg.write_text("[track]\nconfirm_hits = " + "9" * 5000 + "\n")
    code, _, err = run_cli("config", "--config", cfg)
    assert code == 1 and one_error(err).startswith(f"datmo: error: {cfg}: a whole number of more than")


@pytest.mark.parametrize("n", ["²", "٣", "1" * 5000])
def test_scheduler_local_takes_ascii_digits_only(tmp_path, n):
    """`²` and `٣` pass str.isdigit, which int() refuses; 5,000 digits pass it too."""
    pytest.importorskip("distributed")
    src = tmp_path / "a.mcap"
    src.write_bytes(b"a log")
    code, _, err = run_cli("run", src, "-o", tmp_path / "out", "--scheduler", f"local:{n}")
    assert code == 1 and "expected local or local:N with N >= 1 workers" in one_error(err)


# ----------------------------------------------------------------------------------------- traceback


_INTERRUPTED_EXPORT = """
import sys

from datmo_cli import export
from datmo_cli.cli import main

real = export.export


def interrupted(plan, sink, **kw):
    def progress(topic, n):
        raise KeyboardInterrupt  # Ctrl-C after the first batch of rows

    real(plan, sink, features=kw.get("features", False), progress=progress)


export.export = interrupted
main(sys.argv[1:])
"""


def test_export_parquet_interrupted_prints_no_traceback_after_its_error(tmp_path):
    """pyarrow's ParquetWriter, collected after the output file was closed and removed, printed
    "Exception ignored in ParquetWriter.__del__ ... write to closed file" after the clean exit."""
    pytest.importorskip("pyarrow")
    import synthetic_logs as syn

    syn.write(tmp_path / "in.mcap")
    result = subprocess.run(
        [sys.executable, "-c", _INTERRUPTED_EXPORT, "export", "in.mcap", "-o", "t.parquet"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert result.returncode == 130, result.stderr
    assert result.stderr == "datmo: error: interrupted (Ctrl-C); unfinished outputs removed\n", result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.mcap"]


# --------------------------------------------------------------------------------- misleading messages


def test_a_config_with_a_utf8_bom_is_read(tmp_path):
    """A BOM (some editors write one) gave "Invalid statement (at line 1, column 1)"."""
    cfg = tmp_path / "bom.toml"
    cfg.write_bytes(b"\xef\xbb\xbf[track]\nconfirm_hits = 4\n")
    code, out, err = run_cli("config", "--config", cfg)
    assert code == 0, err
    assert "confirm_hits = 4" in out


def test_a_deeply_nested_config_names_the_file(tmp_path):
    cfg = tmp_path / "deep.toml"
    cfg.write_text("[track]\nx = " + "[" * 5000 + "]" * 5000 + "\n")
    code, _, err = run_cli("config", "--config", cfg)
    assert code == 1 and one_error(err).startswith(f"datmo: error: {cfg}: ") and "nested too deeply" in err


CARMEN = "# a CARMEN log\nODOM 0.0 0.0 0.0 0 0 0 1.0 host 1.0\nFLASER 3 1.0 1.0 1.0 0 0 0 0 0 0 1.0 host 1.0\n"


@pytest.mark.parametrize("command", ["track", "features", "segment", "info", "report"])
def test_a_carmen_log_given_for_an_mcap_says_to_convert_it(tmp_path, command):
    """`track` on a CARMEN log said "not an MCAP file (bad magic bytes)", as for any junk."""
    src = tmp_path / "run 1.log"
    src.write_text(CARMEN)
    args = [command, src] + (["-o", tmp_path / "o.mcap"] if command in ("track", "features", "segment") else [])
    code, _, err = run_cli(*args)
    assert code == 1 and one_error(err) == (
        f"datmo: error: {src}: not an MCAP file: it is a CARMEN log; convert it with "
        f"`datmo import '{src}' -o LOG.mcap` first"
    )
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01junk" * 100)
    code, _, err = run_cli(command, junk, *args[2:])
    assert code == 1 and one_error(err) == f"datmo: error: {junk}: not an MCAP file (bad magic bytes)"


@pytest.fixture(scope="module")
def bag_folder(tmp_path_factory):
    """A ROS 2 bag folder (metadata.yaml and one MCAP member) as `datmo run --bag-dir` writes it."""
    import synthetic_logs as syn

    folder = tmp_path_factory.mktemp("bag")
    syn.write(folder / "in.mcap", with_tracks=False, with_truth=False, with_features=False)
    code, _, err = run_cli("run", folder / "in.mcap", "-o", folder / "out", "--bag-dir", "--jobs", "1", "--no-report")
    assert code == 0, err
    return folder / "out" / "in"


@pytest.mark.parametrize("damage", ["junk", "cut"])
def test_a_junk_bag_member_is_named(tmp_path, bag_folder, damage):
    """A bag folder whose member is junk (or cut short) said "cannot read bag", not which file."""
    import shutil

    bag = tmp_path / "bag"
    shutil.copytree(bag_folder, bag)
    member = next(bag.glob("*.mcap"))
    data = member.read_bytes()
    member.write_bytes(b"junk" * 500 if damage == "junk" else data[: len(data) // 2])
    code, _, err = run_cli("import", bag, "-o", tmp_path / "o.mcap")
    assert code == 1 and one_error(err).startswith(
        f"datmo: error: {bag}: bag member {member.name} is not a whole MCAP file"
    )


def test_a_full_disk_in_a_batch_names_the_output_not_the_input(tmp_path, monkeypatch):
    """`run` put the input's name in front of "OUT: no space left on the device": the input seemed at fault."""
    import errno

    from datmo_cli.base import outputs
    from datmo_cli.passes import pipeline, warm

    def full(src, out, **kw):
        raise outputs.os_error(OSError(errno.ENOSPC, "No space left on device"), out, "writing it")

    monkeypatch.setattr(pipeline, "process_file", full)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)
    src = tmp_path / "in.mcap"
    src.write_bytes(b"a log")
    code, _, err = run_cli("run", src, "-o", tmp_path / "out", "--jobs", "1", "--no-report")
    assert code == 1
    line = err.strip().splitlines()[-1]
    assert line == f"datmo: error: {tmp_path / 'out' / 'in.mcap'}: no space left on the device (writing it)", err


def test_plots_of_paths_that_collide_once_joined_are_not_given_twice(tmp_path):
    """a-b/c.mcap, a/b/c.mcap and b/c.mcap: the first two are both a-b-c once joined with '-', which was
    refused as one file "given twice"."""
    from datmo_cli.report.plot_files import plot_paths

    files = [tmp_path / "a-b" / "c.mcap", tmp_path / "a" / "b" / "c.mcap", tmp_path / "b" / "c.mcap"]
    for f in files:
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(b"")
    paths = plot_paths(tmp_path / "q.png", files)
    assert len(set(paths)) == 3 and all(p.parent == tmp_path and p.suffix == ".png" for p in paths)
    from datmo_cli.base.errors import InputError

    with pytest.raises(InputError, match="given twice"):
        plot_paths(tmp_path / "q.png", [files[0], tmp_path / "a-b" / ".." / "a-b" / "c.mcap"])


def _long_parameters(path) -> str:
    import synthetic_logs as syn

    from datmo_cli.logs import cdr, mcapio, types
    from datmo_cli.logs.scan import ScanRun

    value = {f"key_{i:03d}": i / 7 for i in range(40)}
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("track", {"features": value})) as w:
        w.write_scans(ScanRun(syn.STAMPS, syn.room_ranges(), syn.GEOM))
        for k in range(syn.N):
            s = int(syn.STAMPS[k])
            w.write(
                mcapio.TOPIC_TRACKS,
                types.TRACKS,
                s,
                cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": "laser", "tracks": syn.tracks(k)}),
            )
    import json

    return json.dumps(value)


def test_report_piped_prints_parameters_whole_and_a_terminal_cuts_them(tmp_path, monkeypatch):
    """The README promises piped output is never cut; `datmo report FILE | cat` cut the parameter rows with "…"."""
    from test_reliability_escaping import as_terminal

    whole = _long_parameters(tmp_path / "p.mcap")
    assert len(whole) > 500
    code, out, err = run_cli("report", tmp_path / "p.mcap")
    assert code == 0, err
    assert "…" not in out and whole in out
    as_terminal(monkeypatch)
    code, out, err = run_cli("report", tmp_path / "p.mcap")
    assert code == 0 and whole not in out and "…" in out


@pytest.mark.parametrize(
    "text, message",
    [
        ("duration = " + "9" * 5000 + "\n", "a whole number of more than"),
        ("x = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
    ],
)
def test_a_scene_file_too_large_a_number_or_too_deeply_nested_is_one_line(tmp_path, text, message):
    """A --scene file is TOML too: the same cases were exit 70 ("internal error: ValueError", "input too deeply
    nested" without the file)."""
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    code, _, err = run_cli("simulate", "--scene", scene, "-o", tmp_path / "o.mcap")
    assert code == 1 and one_error(err).startswith(f"datmo: error: {scene}: ") and message in err


def test_a_scene_file_with_a_utf8_bom_is_read():
    from importlib import resources

    from datmo_cli.sim.scene import parse_scene

    text = (resources.files("datmo_cli.sim") / "scenes" / "corridor.toml").read_text(encoding="utf-8")
    read = parse_scene("\ufeff" + text, "corridor.toml")  # it was "invalid TOML: Invalid statement"
    import dataclasses

    assert repr(dataclasses.replace(read, text=text)) == repr(parse_scene(text, "corridor.toml"))
