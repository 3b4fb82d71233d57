"""Reliability of outputs and errors: emulate --link, --force over a node, a full disk, errors inside close(),
non-UTF-8 names, read-only folders, long names and a trailing slash.

Each bad case gives one line on stderr naming the file and the problem, a non-zero exit, no traceback, no
temporary file left, and the input unchanged. The signal and write-failure sweeps are in test_fault_injection.
"""

from __future__ import annotations

import errno
import hashlib
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base import outputs
from datmo_cli.base.errors import OutputError
from datmo_cli.cli import clean_error, cli
from datmo_cli.commands.emulate import make_link, remove_link
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanRun

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
HALL = ROOT / "sample_logs" / "hall.mcap"


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The first 20 scans of the hall sample log."""
    run = mcapio.read_run(HALL)
    run = ScanRun(
        run.stamps[:20], run.ranges[:20], run.geometry, None if run.intensities is None else run.intensities[:20]
    )
    path = tmp_path_factory.mktemp("in") / "small.mcap"
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
    return path


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def temps(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")]


def datmo(*args) -> object:
    return CliRunner().invoke(cli, [os.fsdecode(a) if isinstance(a, bytes) else str(a) for a in args])


def one_line_error(res, *needles: str, code: int | None = None) -> str:
    err = res.stderr
    assert res.exit_code != 0 and (code is None or res.exit_code == code), (res.exit_code, res.output)
    assert "Traceback" not in res.output
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: "), err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


# -------------------------------------------------------------------------------------------- emulate --link


def test_emulate_link_refuses_an_existing_file_without_force(tmp_path):
    keep = tmp_path / "f.txt"
    keep.write_text("keep\n")
    res = datmo("emulate", "--link", keep)
    one_line_error(res, str(keep), "exists", "--force")
    assert keep.read_text() == "keep\n" and not keep.is_symlink()


def test_link_replaces_only_a_file_or_link_and_leaves_what_is_not_its_own(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(OutputError, match="FIFO"):
        make_link("/dev/null", fifo, force=True)
    link = tmp_path / "dev.link"
    link.write_text("old")
    made = make_link("/dev/null", link, force=True)
    assert os.readlink(link) == "/dev/null" and not temps(tmp_path)
    os.unlink(link)
    link.write_text("someone else's file")  # replaced after the emulator made its link
    remove_link(link, made)
    assert link.read_text() == "someone else's file"
    os.unlink(link)
    made = make_link("/dev/null", link, force=False)
    remove_link(link, made)
    assert not os.path.lexists(link)


# ----------------------------------------------------------------------------------------- --force over a node


@pytest.mark.parametrize("kind", ["fifo", "chardev", "dir"])
def test_force_never_replaces_a_fifo_device_or_folder(small, tmp_path, kind):
    if kind == "fifo":
        node = tmp_path / "node"
        os.mkfifo(node)
    elif kind == "dir":
        node = tmp_path / "node"
        node.mkdir()
    else:
        node = Path("/dev/null")
    before = digest(small)
    res = datmo("segment", small, "-o", node, "--force")
    one_line_error(res, str(node), "directory" if kind == "dir" else "not a regular file")
    assert node.exists() and (kind != "fifo" or node.is_fifo()) and (kind != "chardev" or node.is_char_device())
    assert digest(small) == before and not temps(tmp_path)


def test_force_replaces_a_symlink_itself_not_its_target(small, tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("keep")
    link = tmp_path / "out.mcap"
    link.symlink_to(target)
    one_line_error(datmo("segment", small, "-o", link), "exists", "--force")
    res = datmo("segment", small, "-o", link, "--force")
    assert res.exit_code == 0, res.output
    assert target.read_text() == "keep" and not link.is_symlink() and len(mcapio.read_run(link)) == 20


# ---------------------------------------------------------------------------------------------- a full disk


def _limited(limit: int):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


@pytest.mark.parametrize(
    "args",
    [["import", str(HALL)], ["simulate", "--scene", "hall", "--duration", "60"], ["segment", str(HALL)]],
    ids=["import", "simulate", "segment"],
)
def test_file_size_limit_is_one_line_and_leaves_nothing(tmp_path, args):
    out = tmp_path / "out.mcap"
    before = digest(HALL)
    proc = subprocess.run(
        [sys.executable, "-m", "datmo_cli", *args, "-o", str(out)],
        capture_output=True,
        text=True,
        preexec_fn=_limited(100_000),
        timeout=120,
    )
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[-1] == f"datmo: error: {out}: file too large for the file-size limit (ulimit -f) (writing it)"
    assert "Traceback" not in proc.stderr
    assert not out.exists() and not temps(tmp_path) and digest(HALL) == before


# ------------------------------------------------------------------------------------ errors inside close()


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), outputs.Terminated(15), OSError(errno.ENOSPC, "full")])
def test_an_error_or_signal_inside_close_removes_the_temporary_file(tmp_path, exc):
    out = tmp_path / "x.mcap"
    w = mcapio.LogWriter(out)
    w.write_scans(mcapio.read_run(HALL))

    def finish() -> None:
        raise exc

    w._writer.finish = finish
    with pytest.raises((KeyboardInterrupt, outputs.Terminated, OutputError)):
        with w:
            pass
    assert not out.exists() and not temps(tmp_path) and not outputs.live()


def test_a_signal_inside_a_critical_section_is_held_until_it_ends():
    with outputs.handle_signals(), pytest.raises(outputs.Terminated) as info:
        with outputs.critical():
            os.kill(os.getpid(), 15)
            for _ in range(1000):  # the handler runs between bytecodes: it must only record the signal
                pass
            held = True
    assert held and info.value.exit_code == 143


# --------------------------------------------------------------------------------------- non-UTF-8 names


def test_non_utf8_input_and_output_names(small, tmp_path):
    src = Path(os.fsdecode(bytes(tmp_path) + b"/in\xff.mcap"))
    src.write_bytes(small.read_bytes())
    out = Path(os.fsdecode(bytes(tmp_path) + b"/out\xfe.mcap"))
    res = datmo("segment", src, "-o", out)
    assert res.exit_code == 0, res.output
    assert "out\\xfe.mcap" in res.stderr and len(mcapio.read_run(out)) == 20
    assert mcapio.read_log(out).metadata["datmo"]["command_line"].count("\\xff") == 1
    res = datmo("segment", src, "-o", out)
    one_line_error(res, "out\\xfe.mcap: exists")
    assert not temps(tmp_path)


# ------------------------------------------------------------------------------------ read-only folders


@pytest.mark.parametrize("code", [errno.EROFS, errno.EACCES, errno.EPERM])
def test_read_only_folder_is_one_line_naming_it(small, tmp_path, monkeypatch, code):
    tracked = tmp_path / "tracked.mcap"
    assert datmo("track", small, "-o", tracked).exit_code == 0
    real = os.open

    def refuse(path, *a, **k):
        if os.fspath(path).endswith(".tmp"):
            raise OSError(code, os.strerror(code), os.fspath(path))
        return real(path, *a, **k)

    monkeypatch.setattr(os, "open", refuse)
    out = tmp_path / "sub" / "out.mcap"
    out.parent.mkdir()
    for args in (
        ["segment", small, "-o", out],
        ["track", small, "-o", out],
        ["import", small, "-o", out],
        ["simulate", "--scene", "hall", "--duration", "1", "-o", out],
        ["report", tracked, "--plot", out.with_suffix(".png")],
    ):
        line = one_line_error(datmo(*args), f"{out.parent}: ", "creating a file there")
        assert outputs.reason(OSError(code, "")) in line
    assert not list(out.parent.iterdir())


def test_unwritable_folder_is_refused_before_any_work(small, tmp_path, monkeypatch):
    real = os.access
    monkeypatch.setattr(os, "access", lambda path, mode, **k: not mode & os.W_OK and real(path, mode, **k))
    one_line_error(datmo("track", small, "-o", tmp_path / "t.mcap"), f"{tmp_path}: output folder is not writable")


# ------------------------------------------------------------------------------------------ long names


def test_a_name_over_255_bytes_is_one_line(small, tmp_path):
    out = tmp_path / ("n" * 300 + ".mcap")
    one_line_error(datmo("segment", small, "-o", out), "file name too long (305 bytes")
    assert not list(tmp_path.iterdir())


def test_a_name_near_the_limit_still_gets_a_temporary_file(small, tmp_path):
    out = tmp_path / ("n" * 250 + ".mcap")
    res = datmo("segment", small, "-o", out)
    assert res.exit_code == 0, res.output
    assert out.exists() and not temps(tmp_path)


# ------------------------------------------------------------------------------------ a trailing slash


@pytest.mark.parametrize("cmd", ["segment", "import", "track"])
def test_trailing_slash_is_refused_not_turned_into_a_file(small, tmp_path, cmd):
    res = datmo(cmd, small, "-o", f"{tmp_path}/newdir/")
    one_line_error(res, "newdir/", "ends with '/'")
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------------------- the one place for errors


def test_clean_error_turns_os_memory_decompression_and_unexpected_errors_into_one_line():
    import zstandard

    assert clean_error(MemoryError()).format_message().startswith("out of memory")
    assert "corrupt compressed data" in clean_error(zstandard.ZstdError("bad frame")).format_message()
    full = clean_error(OSError(errno.ENOSPC, "No space left on device", "/x/y.mcap"))
    assert full.format_message() == "/x/y.mcap: no space left on the device"
    try:
        np.zeros(3)[5]
    except IndexError as exc:
        bug = clean_error(exc)
    assert bug.exit_code == 70 and "internal error: IndexError" in bug.format_message()
    assert "--debug" in bug.format_message() and "\n" not in bug.format_message()
    assert clean_error(KeyboardInterrupt()).exit_code == 130
    assert clean_error(outputs.Terminated(1)).exit_code == 129


def test_a_signal_reported_as_a_system_error_by_a_compiled_call_is_the_signal(small, tmp_path, monkeypatch):
    def boxed(signal_exc):
        def raise_it(*args, **kwargs):
            # CPython's wording when a signal handler raised while a numba dispatcher boxed its result
            raise SystemError(
                "CPUDispatcher(<function track_block>) returned a result with an exception set"
            ) from signal_exc

        return raise_it

    for exc, code, needle in (
        (KeyboardInterrupt(), 130, "interrupted (Ctrl-C)"),
        (outputs.Terminated(15), 143, "stopped by SIGTERM"),
    ):
        monkeypatch.setattr(outputs, "_file_for", boxed(exc))
        res = datmo("segment", small, "-o", tmp_path / "a.mcap")
        one_line_error(res, needle, code=code)
        assert not list(tmp_path.glob(".*.tmp")) and not (tmp_path / "a.mcap").exists()
    assert outputs.interrupt_in(SystemError("x")) is None
    try:
        raise ValueError("a real bug") from KeyboardInterrupt()
    except ValueError as bug:
        assert outputs.interrupt_in(bug) is None  # only the SystemError wrapping is unwrapped
    assert clean_error(SystemError("returned NULL without setting an exception")).exit_code == 70


def test_debug_flag_and_environment_show_the_original_exception(small, tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "_file_for", lambda fd, mode: (_ for _ in ()).throw(MemoryError()))
    plain = datmo("segment", small, "-o", tmp_path / "a.mcap")
    one_line_error(plain, "out of memory")
    res = datmo("--debug", "segment", small, "-o", tmp_path / "a.mcap")
    assert isinstance(res.exception, MemoryError)
    monkeypatch.setenv("DATMO_DEBUG", "1")
    assert isinstance(datmo("segment", small, "-o", tmp_path / "a.mcap").exception, MemoryError)
    assert not temps(tmp_path) and not outputs.live()


def test_a_signal_inside_code_exec_runs_from_a_string_is_sent_again_not_raised_there(monkeypatch):
    """dataclasses make their methods with exec as a module is imported; a KeyboardInterrupt leaving such code
    makes CPython end the process by SIGINT (-2) whatever datmo's exit code: the handler sends it again later."""
    import signal
    import sys

    from datmo_cli.base import outputs

    sent = []

    class Timer:
        def __init__(self, *call):
            self.call = call

        def start(self):
            sent.append(self.call)

    monkeypatch.setattr(outputs.threading, "Timer", Timer)
    frames: list = []
    exec("import sys\nframes.append(sys._getframe())", {"frames": frames})
    assert outputs.must_not_raise(frames[0]) and not outputs.must_not_raise(sys._getframe())
    below: list = []  # `python -c` runs everything below a frame of "<string>": that one does not count
    exec("def outer(frames, inner):\n    inner(frames)", namespace := {})
    namespace["outer"](below, lambda frames: frames.append(sys._getframe()))
    assert below[0].f_back.f_code.co_filename == "<string>" and not outputs.must_not_raise(below[0])
    outputs._handler(signal.SIGINT, frames[0])  # no raise
    assert sent == [(outputs.RESEND_AFTER_S, os.kill, (os.getpid(), signal.SIGINT))]
    with pytest.raises(KeyboardInterrupt):
        outputs._handler(signal.SIGINT, sys._getframe())


def test_a_signal_inside_llvmlites_callbacks_is_sent_again_not_raised_there(monkeypatch):
    """numba's compiler calls back into Python from LLVM (llvmlite's object cache); a stop raised there is ignored
    by ctypes and the process dies of SIGSEGV: the handler sends the signal again a moment later instead."""
    import signal
    import types

    from datmo_cli.base import outputs

    sent = []

    class Timer:
        def __init__(self, delay, fn, args):
            self.call = (delay, fn, args)

        def start(self):
            sent.append(self.call)

    monkeypatch.setattr(outputs.threading, "Timer", Timer)
    code = compile("pass", "/venv/lib/python3.11/site-packages/llvmlite/binding/executionengine.py", "exec")
    inner = types.SimpleNamespace(f_code=types.SimpleNamespace(co_filename=__file__), f_back=None)
    native = types.SimpleNamespace(f_code=code, f_back=None)
    inner.f_back = native  # a datmo frame called from inside llvmlite's callback
    outputs._handler(signal.SIGTERM, inner)  # no raise
    assert sent == [(outputs.RESEND_AFTER_S, os.kill, (os.getpid(), signal.SIGTERM))]
    with pytest.raises(outputs.Terminated):
        outputs._handler(
            signal.SIGTERM, types.SimpleNamespace(f_code=types.SimpleNamespace(co_filename=__file__), f_back=None)
        )
