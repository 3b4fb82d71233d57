"""Nothing raw to a terminal or a page (issue #33, third round): one escaping rule (text.printable) for every
text that came from a log, a client or a config, wherever it goes: stdout or stderr (CSV written to a
terminal included), Markdown (text.markdown); a client's or a library's repeated messages are rate-limited,
and a library's own messages of several lines are printed line by line, each escaped."""

from __future__ import annotations

import asyncio
import csv
import io
import json
import re
import signal
import subprocess
import sys
import unicodedata

import numpy as np
import pytest
from click.testing import CliRunner
from test_reliability_escaping import LINK, as_terminal

from datmo_cli import cli as cli_module
from datmo_cli.base import progress
from datmo_cli.base.text import printable
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcap_writer, mcapio, types
from datmo_cli.logs.scan import ScanGeometry, ScanRun

pytestmark = pytest.mark.cli

INVISIBLE = "\u200f\u200b\ufeff\u2060\u00ad\u061c\U000e0041"  # RLM, ZWSP, BOM, word joiner, soft hyphen, ALM, a tag
TITLE = "\x1b]0;owned\x07"  # OSC 0: sets the terminal window's title
FRAME = f"{LINK}{TITLE}\x1b[2J:smile:{INVISIBLE}# <b>x</b> ![i](http://evil.example/i.png) [l](http://e/)"
CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")


def run_cli(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result.exit_code, result.stdout, result.stderr


def raw(text: str) -> list[str]:
    """What of the hostile strings reached `text` unescaped."""
    found = [c for c in "\x1b\x07\u202e" + INVISIBLE if c in text]
    return found + (["newline inside a line"] if "\x0a" in text.replace("\n", "") else [])


# ------------------------------------------------------------------------------------------ text.py


def test_every_format_character_is_escaped():
    """Invisible characters (category Cf: bidirectional marks, zero-width space and joiners, BOM, soft hyphen,
    tags) make a name look like another or reorder what follows: every one is escaped."""
    fmt = [chr(c) for c in range(sys.maxunicode + 1) if unicodedata.category(chr(c)) == "Cf"]
    assert len(fmt) > 150
    shown = printable("".join(fmt))
    assert not any(c in shown for c in fmt) and shown.isascii()
    assert printable("a\u200fb\ufeff\U000e0041") == "a\\u200fb\\ufeff\\U000e0041"
    assert printable(shown) == shown  # still idempotent
    assert printable("café 走廊 ° 👍") == "café 走廊 ° 👍"


def test_markdown_escapes_what_would_render():
    from datmo_cli.base.text import markdown

    text = markdown("# <b>x</b> ![i](http://e/i.png) [l](u) *a* _b_ `c` | ~d~ &amp; \x1b")
    assert text == (
        "\\# \\<b\\>x\\</b\\> \\!\\[i\\](http://e/i.png) \\[l\\](u) \\*a\\* \\_b\\_ \\`c\\` \\| \\~d\\~ \\&amp; \\\\x1b"
    )


def test_printable_lines_keeps_a_librarys_lines():
    from datmo_cli.base.text import printable_lines

    assert printable_lines("Port 8787 is in use.\nHosting on 4\x1b[2J\n\n") == [
        "Port 8787 is in use.",
        "Hosting on 4\\x1b[2J",
    ]


# ------------------------------------------------------------------------------- a log's header


def test_emoji_codes_and_invisible_characters_of_a_logs_header_print_as_written(tmp_path, monkeypatch):
    """The MCAP header's library (`written by ...`) held emoji codes (rich turned `:smile:` into an emoji) and
    invisible characters (passed raw)."""
    import synthetic_logs as syn

    monkeypatch.setattr(mcap_writer, "__version__", f":smile: :thumbs_up:{INVISIBLE}")
    syn.write(tmp_path / "h.mcap")
    monkeypatch.undo()
    as_terminal(monkeypatch)
    code, out, err = run_cli("info", tmp_path / "h.mcap")
    assert code == 0, err
    line = out.splitlines()[0]
    assert "written by datmo :smile: :thumbs_up:\\u200f\\u200b\\ufeff\\u2060\\xad\\u061c\\U000e0041" in line, line
    assert "😄" not in out and "👍" not in out and not raw(out)


# ------------------------------------------------------------------------------ export and report


@pytest.fixture(scope="module")
def hostile_frames(tmp_path_factory):
    """A processed log whose tracks' and features' frame id is FRAME."""
    import synthetic_logs as syn

    path = tmp_path_factory.mktemp("frames") / "p.mcap"
    geometry = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, FRAME)
    with mcapio.LogWriter(path) as w:
        w.write_scans(ScanRun(syn.STAMPS, syn.room_ranges(), geometry))
        w.add_metadata("datmo", {"tool": "datmo", "version": "0", "command": "track", "command_line": "x"})
        for k in range(syn.N):
            s = int(syn.STAMPS[k])
            for topic, typ, extra in (
                (mcapio.TOPIC_TRACKS, types.TRACKS, {"tracks": syn.tracks(k)}),
                (mcapio.TOPIC_LANDMARKS, types.LANDMARKS, {"landmarks": syn.landmarks(k)}),
            ):
                w.write(topic, typ, s, cdr.encode(typ, {"stamp_ns": s, "frame_id": FRAME, **extra}))
    return path


def test_export_csv_to_a_terminal_escapes_a_logs_frame_ids(hostile_frames, monkeypatch):
    code, piped, err = run_cli("export", hostile_frames, "-o", "-", "--format", "csv")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(piped)))
    assert rows and {r["frame_id"] for r in rows} == {FRAME}  # a pipe or a file gets the data as it is
    as_terminal(monkeypatch)
    code, shown, err = run_cli("export", hostile_frames, "-o", "-", "--format", "csv")
    assert code == 0, err
    assert not raw(shown), raw(shown)
    rows = list(csv.DictReader(io.StringIO(shown)))
    assert len(rows) == len(list(csv.DictReader(io.StringIO(piped)))) and {r["frame_id"] for r in rows} == {
        printable(FRAME)
    }
    code, ndjson, err = run_cli("export", hostile_frames, "-o", "-", "--format", "ndjson")
    assert code == 0 and not raw(ndjson) and json.loads(ndjson.splitlines()[0])["frame_id"] == FRAME


def test_report_markdown_escapes_a_logs_frame_ids(hostile_frames):
    code, out, err = run_cli("report", hostile_frames, "--format", "markdown")
    assert code == 0, err
    assert not raw(out), raw(out)
    headings = [line for line in out.splitlines() if "landmarks" in line and line.startswith("### ")]
    assert headings, out
    for bad in ("<b>", "![", "[l]", "# <"):
        assert bad not in out, bad
    assert not re.search(r"(?<!\\)\]\(", out)  # no link or image: every `](` escaped
    assert "\\<b\\>x\\</b\\>" in headings[0] and "\\!\\[i\\]" in headings[0]


# ------------------------------------------------------------------------------------------ play


async def _junk_client(url: str, n: int) -> None:
    import websockets

    async with websockets.connect(url, subprotocols=["foxglove.websocket.v1"], max_size=None) as ws:
        channels: list = []
        while not channels:  # serverInfo, then the channels
            frame = await asyncio.wait_for(ws.recv(), 60)
            if isinstance(frame, str) and json.loads(frame).get("op") == "advertise":
                channels = json.loads(frame)["channels"]

        async def status() -> None:  # the server's answer to a bad frame: read before the next is sent, so its
            while True:  # queue to this client stays short (a client that lags that far is disconnected)
                frame = await asyncio.wait_for(ws.recv(), 60)
                if isinstance(frame, str) and json.loads(frame).get("op") == "status":
                    return

        await ws.send(json.dumps({"op": f"evil{TITLE}{LINK}\nforged line\x1b[2J"}))
        await status()
        for i in range(n):
            await ws.send(json.dumps({"op": f"junk{i}"}))
            await status()
        # every bad frame answered: the server has read them all


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_play_escapes_and_rate_limits_a_clients_bad_frames(tmp_path):
    """2,000 junk frames gave 2,003 stderr lines, and a client's op name reached stderr with its escapes and
    line breaks."""
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    import synthetic_logs as syn

    syn.write(tmp_path / "p.mcap")
    proc = subprocess.Popen(
        [sys.executable, "-c", "from datmo_cli.cli import main; main()", "play", "p.mcap", "--port", "0", "--loop"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        url = re.search(r"on (ws://\S+)$", proc.stdout.readline().strip()).group(1)
        asyncio.run(_junk_client(url, 2000))
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    lines = err.splitlines()
    assert 5 <= len(lines) <= 12, err[:3000]
    assert not CONTROL.search(err) and "\u2028" not in err, err[:3000]
    assert not any(line.startswith("forged line") for line in lines)
    assert "evil\\x1b]0;owned\\x07" in err and "\\x0aforged line" in err
    held = re.search(r"([\d,]+) more such messages not shown", err)
    assert held and int(held.group(1).replace(",", "")) >= 1990, err[-2000:]


def test_limited_says_the_first_then_at_most_once_a_period():
    said: list[str] = []
    limited = progress.Limited("p", burst=2, every_s=3600, sink=said.append)
    for i in range(100):
        limited(f"bad {i}\x1b[2J\n", "client")
    limited("other kind", "publisher")
    limited.close()
    assert said == [
        "p: bad 0\\x1b[2J\\x0a",
        "p: bad 1\\x1b[2J\\x0a",
        "p: more such messages are shown at most once a minute",
        "p: other kind",
        "p: 98 more such messages not shown",
    ]


# ------------------------------------------------------------------------------ a library's warning


def test_a_dask_warning_of_several_lines_prints_line_by_line(capsys):
    """A Dask warning spans lines: it printed as one line with `\\x0a` in the middle of its sentences."""
    message = UserWarning("Port 8787 is already in use.\nPerhaps you already have a cluster running?\nHosting on 1")
    cli_module._show_warning(message, UserWarning, "/x/site-packages/distributed/node.py", 195)
    assert capsys.readouterr().err.splitlines() == [
        "datmo: warning: Port 8787 is already in use.",
        "  Perhaps you already have a cluster running?",
        "  Hosting on 1",
    ]
    cli_module._show_warning(UserWarning("a topic\n\x1b[2J"), UserWarning, cli_module.__file__, 1)
    assert capsys.readouterr().err == "datmo: warning: a topic\\x0a\\x1b[2J\n"  # datmo's own: one line


def test_node_rate_limits_what_a_publisher_makes_it_say(monkeypatch):
    """A publisher alternating two scan geometries made the node say "tracking starts over" for every scan."""
    from datmo_cli.ros2 import node as node_module

    class Publisher:
        """A stand-in for the DDS node: 1,000 restarts whose reason holds a publisher's frame id, then Ctrl-C."""

        def __init__(self, domain, scan_topic, odom_topic, cfg, say, **graph) -> None:
            self.say, self.scan_topic, self.odom_topic, self.topics = say, scan_topic, None, ["/datmo/tracks"]
            self.feed = type("Feed", (), {"failure": None})()
            self.name, self.logged = "/datmo", []
            published.append(self)

        def log(self, level: int, line: str) -> None:
            self.logged.append((level, line))

        def spin(self) -> None:
            for k in range(1000):
                self.say(f"datmo node: the scans' geometry changed ({k} beams in 'laser{TITLE}'): tracking starts over")
            raise KeyboardInterrupt

        def close(self) -> None:
            pass

        def summary(self) -> str:
            return "1,000 scans received"

    published: list[Publisher] = []
    monkeypatch.setattr(node_module, "Node", Publisher)
    monkeypatch.setattr("datmo_cli.ros2.dds.domain_id", lambda value=None: 0)
    code, out, err = run_cli("node")
    assert code == 130
    lines = err.splitlines()
    assert len(lines) <= 10 and not CONTROL.search(err), err[:3000]
    assert "datmo node: 995 more such messages not shown" in lines
    warnings = [line for level, line in published[0].logged if level == 30]  # /rosout as limited as stderr
    assert len(warnings) <= 8 and "datmo node: 995 more such messages not shown" in warnings


def test_config_listing_escapes_what_a_config_gave(tmp_path):
    """`datmo config` printed a string value's invisible characters (and DEL, which TOML refuses) raw."""
    cfg = tmp_path / "c.toml"
    cfg.write_text('[features]\nleg_model = "x\\u001b[2J\\u200fy\\u007f\\ufeff"\n')
    code, out, err = run_cli("config", "--config", cfg)
    assert code == 0, err
    assert not raw(out) and "\x7f" not in out
    assert 'leg_model = "x\\u001b[2J\\u200fy\\u007f\\ufeff"' in out
    back = tmp_path / "back.toml"
    back.write_text(out)
    code, again, err = run_cli("config", "--config", back)
    assert code == 0 and 'leg_model = "x\\u001b[2J\\u200fy\\u007f\\ufeff"' in again  # reads back the same value


def test_a_librarys_log_goes_through_one_escaping_rate_limited_path(capsys):
    """What Dask logs (errors of the scheduler, the nannies and the workers, whose text may quote a task's
    error, and so a log's strings) printed raw through its own handler."""
    import logging

    said: list[str] = []
    limited = progress.Limited("datmo: dask", multiline=True, sink=said.append)
    log = logging.getLogger("distributed.test_reliability_terminal")
    restore = progress.route_logs(("distributed",), limited, level=logging.ERROR)
    try:
        log.warning("not shown: below the level")
        for _ in range(10):
            log.error("Compute Failed\nKey: x\nException: 'frame\x1b[2J'", exc_info=(ValueError, ValueError(), None))
    finally:
        restore()
        limited.close()
    assert said[0] == "datmo: dask: Compute Failed\n  Key: x\n  Exception: 'frame\\x1b[2J'"
    assert len(said) == 7 and said[-1] == "datmo: dask: 5 more such messages not shown"
    assert capsys.readouterr().err == ""


def test_a_progress_bar_shows_a_file_name_as_it_is(monkeypatch):
    """`import` draws `reading NAME` on a terminal: a file name holding `[/]` crashed rich's markup (exit 70),
    and its escape sequences reached the terminal."""
    monkeypatch.setattr(progress, "_drawn", lambda: True)
    with progress.bar(f"reading a[/]b{TITLE}.log", 10, info=True) as b:
        b.update(3, info="[/]x")
        b.advance(1, description=f"[/]{TITLE}")
        b.progress.refresh()  # rendered now: the description and the info column as Rich markup
        task = b.progress.tasks[0]
        from rich.text import Text

        assert Text.from_markup(task.description).plain == f"[/]{printable(TITLE)}"
        assert Text.from_markup(task.fields["info"]).plain == "[/]x"
