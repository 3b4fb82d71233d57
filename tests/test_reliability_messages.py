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
