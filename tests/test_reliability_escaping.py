"""Strings from a log reach the terminal as themselves.

A log's topic, schema and frame names and its metadata (the provenance's command line and parameters among
them) are data anyone can write: printed by `info`, `report` or `run`'s report they must not be read as Rich
markup (`[/]` once crashed all three with exit 70) nor reach the terminal as escape sequences (clearing the
screen, an OSC 8 link). In CSV a text field starting like a formula is neutralised (`'` before it).
"""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base import progress
from datmo_cli.base.text import markup, printable
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun

pytestmark = pytest.mark.cli

CLEAR = "\x1b[2J"
LINK = "\x1b]8;;http://evil.example/\x1b\\click me\x1b]8;;\x1b\\"
HOSTILE = f"[/]{CLEAR}[link=http://evil.example/]x[/link]{LINK}\u202eevil\n"
SHOWN = "[/]\\x1b[2J[link=http://evil.example/]x[/link]"  # how the start of HOSTILE must be shown


def run_cli(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result.exit_code, result.stdout, result.stderr


def assert_shown_safely(text: str) -> None:
    """No escape or control character other than newlines, and the hostile string shown as itself."""
    assert "\x1b" not in text and "\u202e" not in text and "\x07" not in text
    assert SHOWN in text, text[:2000]


# ------------------------------------------------------------------------------------------ text.py


def test_printable_escapes_controls_and_keeps_ordinary_text():
    assert printable(HOSTILE) == (
        "[/]\\x1b[2J[link=http://evil.example/]x[/link]\\x1b]8;;http://evil.example/"
        "\\x1b\\click me\\x1b]8;;\\x1b\\\\u202eevil\\x0a"
    )
    assert printable("a\tb\rc\x7f\x9b\u2028") == "a\\x09b\\x0dc\\x7f\\x9b\\u2028"
    ordinary = "hall: 90.0° to -90.0°, café, 走廊, /datmo/markers/tracks"
    assert printable(ordinary) == ordinary
    assert printable(printable(HOSTILE)) == printable(HOSTILE)  # idempotent


def test_markup_prints_as_itself():
    from rich.console import Console

    plain = Console(file=io.StringIO(), width=300, no_color=True)
    for text in ("[/]", "[bold]x[/bold]", "a\\", "[link=http://x]y[/link]", "\\[/]"):
        plain.print(f"[bold]{markup(text)}[/]")
    assert plain.file.getvalue().splitlines() == ["[/]", "[bold]x[/bold]", "a\\", "[link=http://x]y[/link]", "\\[/]"]


# ------------------------------------------------------------------------------------- a hostile log


def write_hostile(path, *, processed: bool) -> None:
    """A log whose every string is HOSTILE: the scans' frame, a second topic's name and schema name, the
    metadata's names, keys and values; with `processed`, tracks, features and landmarks (in frame HOSTILE)
    and provenance metadata whose command line, version and parameters are HOSTILE."""
    import synthetic_logs as syn

    geometry = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, HOSTILE)
    run = ScanRun(syn.STAMPS, syn.room_ranges(), geometry)
    with mcapio.LogWriter(path, force=True) as w:
        w.write_scans(run)
        cid = w.channel(HOSTILE, types.LASERSCAN, schema_text=types.schema_text(types.LASERSCAN))
        w.write_ids(cid, run.stamps[:2], [b"\0\1\0\0"] * 2)
        other = w.channel("/other", HOSTILE, schema_text="int32 x\n")
        w.write_ids(other, run.stamps[:1], [b"\0\1\0\0\0\0\0\0"])
        w.add_metadata(HOSTILE, {HOSTILE: HOSTILE})
        if not processed:
            return
        w.add_metadata("datmo", {"tool": "datmo", "version": HOSTILE, "command": "track", "command_line": HOSTILE})
        w.add_metadata("datmo.params", {HOSTILE: json.dumps(HOSTILE), "features": json.dumps({"frame": HOSTILE})})
        for k in range(syn.N):
            s = int(syn.STAMPS[k])
            w.write(
                mcapio.TOPIC_FEATURES,
                types.FEATURES,
                s,
                cdr.encode(types.FEATURES, {"stamp_ns": s, "frame_id": HOSTILE, **syn.features(k)}),
            )
            w.write(
                mcapio.TOPIC_LANDMARKS,
                types.LANDMARKS,
                s,
                cdr.encode(types.LANDMARKS, {"stamp_ns": s, "frame_id": HOSTILE, "landmarks": syn.landmarks(k)}),
            )
            w.write(
                mcapio.TOPIC_TRACKS,
                types.TRACKS,
                s,
                cdr.encode(types.TRACKS, {"stamp_ns": s, "frame_id": HOSTILE, "tracks": syn.tracks(k)}),
            )


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile")
    raw, processed = folder / "raw.mcap", folder / "processed.mcap"
    write_hostile(raw, processed=False)
    write_hostile(processed, processed=True)
    return raw, processed


def as_terminal(monkeypatch) -> None:
    """Tables printed as on a terminal (boxed, styled), not as on a pipe (plain columns)."""
    monkeypatch.setattr(progress, "_isatty", lambda stream: True)
    monkeypatch.setenv("COLUMNS", "2000")  # wide enough that no cell is folded


@pytest.fixture(params=["pipe", "terminal"])
def terminal(request, monkeypatch):
    if request.param == "terminal":
        as_terminal(monkeypatch)
    return request.param


def test_info_shows_a_hostile_log_as_it_is(hostile, terminal):
    code, out, err = run_cli("info", hostile[0])
    assert code == 0, err
    assert_shown_safely(out)
    for what in ("\\u202eevil\\x0a", "sensor_msgs/msg/LaserScan"):
        assert what in out
    assert out.count(SHOWN) >= 6  # the frame, a topic, a schema name, a metadata record's name, key and value


@pytest.mark.parametrize(
    "fmt, on_terminal", [("rich", False), ("rich", True), ("markdown", False), ("csv", False), ("json", False)]
)
def test_report_shows_a_hostile_log_as_it_is(hostile, monkeypatch, fmt, on_terminal):
    if on_terminal:
        as_terminal(monkeypatch)
    code, out, err = run_cli("report", hostile[1], "--format", fmt)
    assert code == 0, err
    assert "\x1b" not in out and "\u202e" not in out
    if fmt == "json":
        assert json.loads(out)["files"][0]["run"]["command"] == HOSTILE  # JSON keeps the string, escaped by JSON
    elif fmt == "markdown":  # escaped for Markdown too (text.markdown): `[/]` shows as `\[/\]`
        from datmo_cli.base.text import markdown

        assert "\x1b" not in out and markdown(SHOWN) in out, out[:2000]
    elif fmt != "csv":
        assert_shown_safely(out)  # the command line, the version, a parameter's name and value, the landmark frame


def test_run_report_and_errors_of_a_hostile_input(tmp_path, hostile, monkeypatch):
    """`run` on an input whose path holds `[/]` (a folder "a[" holding "]b.mcap") and whose strings are
    hostile: its table, its report and its error lines print them as they are."""
    folder = tmp_path / "a["
    folder.mkdir()
    (folder / "]b.mcap").write_bytes(hostile[0].read_bytes())
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli("run", "a[/]b.mcap", "-o", "out", "--jobs", "1")
    assert code == 0, err
    assert "[/]b.mcap" in out and "\x1b" not in out + err and "\u202e" not in out + err


def test_warnings_and_errors_from_a_log_are_one_printable_line(tmp_path):
    """A warning or an error naming a log's topic or type: one line, its control characters escaped."""
    path = tmp_path / "in.mcap"
    with mcapio.LogWriter(path) as w:
        cid = w.channel(mcapio.TOPIC_SCAN, HOSTILE, schema_text="int32 x\n")
        w.write_ids(cid, [1_600_000_000_000_000_000], [b"\0\1\0\0\0\0\0\0"])
    code, out, err = run_cli("track", path, "-o", tmp_path / "out.mcap")
    assert code == 1 and err.count("\n") == 1 and err.startswith("datmo: error: "), err
    assert "\x1b" not in err and "\u202e" not in err and printable(HOSTILE) in err


# ------------------------------------------------------------------------------------------- CSV


@pytest.mark.parametrize("name", ["=HYPERLINK(1).mcap", "+1.mcap", "@SUM(1).mcap", "-x.mcap"])
@pytest.mark.parametrize("tracks", [False, True])
def test_report_csv_neutralises_a_file_name_like_a_formula(tmp_path, monkeypatch, name, tracks):
    import synthetic_logs as syn

    syn.write(tmp_path / name)
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli("report", "--format", "csv", *(["--tracks"] if tracks else []), "--", name)
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert rows and all(r["file"] in ("'" + name, "total") for r in rows)
    assert not any(v.startswith(("=", "+", "@")) for r in rows for v in r.values())
    negative = [v for r in rows for k, v in r.items() if k != "file" and v.startswith("-")]
    assert all(float(v) < 0 for v in negative)  # negative numbers (the tracks' last positions) stay numbers
    assert bool(negative) == tracks
