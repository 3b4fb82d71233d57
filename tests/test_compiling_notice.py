"""The notice that numba is compiling: shown only while a stage's first progress report is late."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest

from datmo_cli.base.numba_runtime import NOTICE, compile_notice

pytestmark = pytest.mark.unit


class FakeBar:
    """What compile_notice uses of rich's Progress: update() and tasks."""

    def __init__(self, description: str) -> None:
        self.task = SimpleNamespace(id=0, description=description)
        self.tasks = [self.task]
        self.descriptions: list[str] = []
        self.completed: list[int] = []

    def update(self, task, description=None, completed=None, total=None) -> None:
        if description is not None:
            self.task.description = description
            self.descriptions.append(description)
        if completed is not None:
            self.completed.append(completed)


def test_a_late_first_report_says_the_kernels_compile_then_the_label_returns():
    bar = FakeBar("features")
    with compile_notice(bar, 0, delay=0.05) as report:
        time.sleep(0.3)
        report(256, 300)
        report(300, 300)
    assert bar.descriptions == [f"features: {NOTICE}", "features"]
    assert bar.completed == [256, 300]


def test_a_prompt_first_report_says_nothing():
    bar = FakeBar("features")
    with compile_notice(bar, 0, delay=0.2) as report:
        report(1, 2)
    time.sleep(0.4)
    assert bar.descriptions == []


def test_each_stage_started_with_zero_done_is_watched():
    bar = FakeBar("reading")
    with compile_notice(bar, 0, delay=0.05, armed=False) as report:
        time.sleep(0.15)  # not armed: reading the input says nothing
        bar.update(0, description="features")
        report(0, 10)
        report(10, 10)  # prompt: nothing
        bar.update(0, description="tracking")
        report(0, 10)
        time.sleep(0.3)  # late: compiling
        report(1, 10)
    assert bar.descriptions == ["features", "tracking", f"tracking: {NOTICE}", "tracking"]


def test_a_slow_block_is_said_once_on_stderr(capsys):
    from datmo_cli.base.numba_runtime import said_if_slow

    with said_if_slow(delay=0.05):
        time.sleep(0.3)
    with said_if_slow(delay=0.5):
        pass
    time.sleep(0.6)
    assert capsys.readouterr().err == f"{NOTICE}...\n"


def _fake_cache(root, stamp: float) -> None:
    """An index file in numba's NUMBA_CACHE_DIR layout for perception/segmentation.py, dated `stamp`."""
    import hashlib
    import os

    import datmo_cli

    folder = os.path.join(os.path.dirname(os.path.abspath(datmo_cli.__file__)), "perception")
    sub = root / f"perception_{hashlib.sha1(folder.encode()).hexdigest()}"
    sub.mkdir(parents=True)
    index = sub / "segmentation.segment_scan-10.py311.nbi"
    index.write_bytes(b"")
    os.utime(index, (stamp, stamp))


def test_a_cache_in_numba_cache_dir_is_judged_by_its_index_files(tmp_path, monkeypatch):
    from datmo_cli.base import numba_runtime

    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty"))
    assert numba_runtime.cache_looks_stale()  # nothing there: the kernels will compile
    _fake_cache(tmp_path / "cache", time.time() + 3600)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    assert not numba_runtime.cache_looks_stale()  # cached after its source was written: loaded, nothing to say
    _fake_cache(tmp_path / "old", 1_000.0)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "old"))
    assert numba_runtime.cache_looks_stale()  # the source was edited since


def test_the_compile_line_comes_at_once_on_a_redirected_stderr(tmp_path):
    """A process about to compile says so on stderr (a file here, not a terminal) before it imports numba, once,
    with the time it takes; one whose cache is complete says nothing."""
    import os
    import subprocess
    import sys

    code = (
        "import sys; from datmo_cli.base.numba_runtime import prepare; prepare(); prepare(); "
        "print('numba' in ' '.join(sys.modules))"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "DATMO_COMPILE_NOTICE")}
    said = []
    for cache in ("empty", "cache"):
        if cache == "cache":
            _fake_cache(tmp_path / cache, time.time() + 3600)
        with open(tmp_path / f"{cache}.err", "w") as err:
            done = subprocess.run(
                [sys.executable, "-c", code],
                env={**env, "NUMBA_CACHE_DIR": str(tmp_path / cache)},
                stderr=err,
                stdout=subprocess.PIPE,
                text=True,
                timeout=120,
            )
        assert done.returncode == 0 and done.stdout.strip() == "True"
        said.append((tmp_path / f"{cache}.err").read_text())
    assert said[0] == f"datmo: {NOTICE}; cached for the next runs (`datmo warm-up` compiles them ahead)\n"
    assert "about 2.5 min" in said[0]
    assert said[1] == ""


@pytest.mark.slow
def test_warm_up_loads_or_compiles_every_kernel_and_says_how_long():
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    result = CliRunner().invoke(cli, ["warm-up"])
    assert result.exit_code == 0, result.output
    assert "the numba kernels in" in result.output and "later runs load them from the cache" in result.output
    assert CliRunner().invoke(cli, ["warm-up", "-q"]).output == ""


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["run", "in.mcap", "-o", "out"], True),
        (["--debug", "features", "in.mcap"], True),
        (["warm-up"], True),
        (["run", "--help"], False),
        (["track", "in.mcap", "-q"], False),
        (["info", "in.mcap"], False),
        ([], False),
    ],
)
def test_a_kernel_command_says_it_compiles_before_its_own_imports(tmp_path, monkeypatch, capsys, args, said):
    from datmo_cli import cli
    from datmo_cli.base import numba_runtime

    monkeypatch.delenv("DATMO_COMPILE_NOTICE", raising=False)
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty"))  # nothing cached
    monkeypatch.setattr(numba_runtime, "_SAID", False)
    monkeypatch.setattr(cli, "_ARGS", list(args))
    cli._say_compiling()
    cli._say_compiling()
    assert capsys.readouterr().err == (
        f"datmo: {NOTICE}; cached for the next runs (`datmo warm-up` compiles them ahead)\n" if said else ""
    )
    monkeypatch.setenv("DATMO_COMPILE_NOTICE", "0")
    monkeypatch.setattr(numba_runtime, "_SAID", False)
    cli._say_compiling()
    assert capsys.readouterr().err == ""


def test_warm_up_says_it_compiled_when_the_cache_was_stale(monkeypatch):
    """The command line's first step says the line; the command still knows it compiled (not 'loaded')."""
    from click.testing import CliRunner

    from datmo_cli.base import numba_runtime
    from datmo_cli.cli import cli
    from datmo_cli.passes import warm

    steps = []
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setattr(numba_runtime, "_SAID", False)
    monkeypatch.setattr(warm, "warm_up", lambda progress=None: steps.append(progress))
    result = CliRunner().invoke(cli, ["warm-up"])
    assert result.exit_code == 0, result.output
    assert "compiled the numba kernels in" in result.output and len(steps) == 1


def test_a_first_run_in_one_process_compiles_only_the_kernels_it_runs(monkeypatch, tmp_path):
    """With one input and one process, `datmo run` does not warm up every kernel of the pipeline (the simulator,
    scan matching, the markers, the patrol scene) when the cache looks stale: the run compiles what it runs."""
    from click.testing import CliRunner

    from datmo_cli.base import numba_runtime
    from datmo_cli.cli import cli
    from datmo_cli.passes import warm

    log = tmp_path / "one.mcap"
    assert CliRunner().invoke(cli, ["simulate", "--scene", "hall", "--duration", "0.2", "-o", str(log)]).exit_code == 0
    warmed = []
    monkeypatch.setattr(numba_runtime, "cache_looks_stale", lambda: True)
    monkeypatch.setattr(numba_runtime, "_SAID", False)
    monkeypatch.setattr(warm, "warm_up", lambda progress=None: warmed.append(progress))
    result = CliRunner().invoke(cli, ["run", str(log), "-o", str(tmp_path / "out"), "--no-report"])
    assert result.exit_code == 0, result.output
    assert warmed == [] and (tmp_path / "out" / "one.mcap").is_file()
