"""CSV text fields that a spreadsheet would run as a formula are written as text: the shared
function of every CSV writer, and `datmo export`'s CSV of a log whose frame id and file name are formulas."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base.csvsafe import neutralise, neutralise_row
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types

pytestmark = pytest.mark.cli


@pytest.mark.parametrize(
    ("text", "written"),
    [
        ("=1+2", "'=1+2"),
        ('=HYPERLINK("http://example.org","x")', '\'=HYPERLINK("http://example.org","x")'),
        ("+1", "'+1"),
        ("@SUM(A1)", "'@SUM(A1)"),
        ("-2+3", "'-2+3"),
        ("-cmd|' /C calc'!A0", "'-cmd|' /C calc'!A0"),
        ("-inf", "'-inf"),
        ("\t=1", "'\t=1"),
        ("\r=1", "'\r=1"),
        ("-1.5", "-1.5"),
        ("-2e3", "-2e3"),
        ("-.5", "-.5"),
        ("laser", "laser"),
        ("a=b", "a=b"),
        ("", ""),
    ],
)
def test_neutralise(text, written):
    assert neutralise(text) == written


def test_neutralise_row_touches_text_only():
    assert neutralise_row(["=x", 3, None, -1.5, "ok"]) == ["'=x", 3, None, -1.5, "ok"]


FORMULA_FRAME = '=HYPERLINK("http://example.org","click")'


def formula_log(path: Path) -> Path:
    """A processed-looking log: two Tracks messages, one track each, in a frame named like a formula."""
    track = np.zeros(1, cdr.element_dtype(types.TRACK))
    track["id"], track["x"], track["world_x"] = 7, 1.5, np.nan
    with mcapio.LogWriter(path) as w:
        for k in range(2):
            stamp = 1_000_000_000 + k * 200_000_000
            w.write(
                mcapio.TOPIC_TRACKS,
                types.TRACKS,
                stamp,
                cdr.encode(types.TRACKS, {"stamp_ns": stamp, "frame_id": FORMULA_FRAME, "tracks": track}),
            )
    return path


def test_export_csv_writes_formulas_as_text(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    formula_log(tmp_path / "@cmd.mcap")
    assert CliRunner().invoke(cli, ["export", "@cmd.mcap", "-o", "t.csv"]).exit_code == 0
    rows = list(csv.DictReader(io.StringIO((tmp_path / "t.csv").read_text())))
    assert [(r["file"], r["frame_id"], r["x_m"]) for r in rows] == [("'@cmd.mcap", "'" + FORMULA_FRAME, "1.5")] * 2
    # NDJSON carries the values as they are: no spreadsheet opens it
    assert CliRunner().invoke(cli, ["export", "@cmd.mcap", "-o", "t.ndjson"]).exit_code == 0
    first = json.loads((tmp_path / "t.ndjson").read_text().splitlines()[0])
    assert (first["file"], first["frame_id"]) == ("@cmd.mcap", FORMULA_FRAME)
