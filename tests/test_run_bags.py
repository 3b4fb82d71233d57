"""`datmo run` on bags resumes as on logs: the batch keys a bag by its own path and SHA-256, with
--topic/--odom-topic in the parameters' hash; only the tasks that run convert their bag (in the worker, into a
temporary MCAP beside the output, removed on every way out); the output's provenance names the bag."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from fuzzing import tally
from test_cli_conventions import N_SCANS, write_ros1_bag, write_ros2_bag

from datmo_cli.base.errors import InputError
from datmo_cli.cli import cli
from datmo_cli.logs import importers, mcapio

pytestmark = pytest.mark.cli


def invoke(*args, quiet: bool = True):
    return CliRunner().invoke(cli, ["run", *map(str, args), "--no-report", *(["-q"] if quiet else [])])


def latest(out: Path) -> dict[str, dict]:
    """The manifest's latest line of each input."""
    lines = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]
    return {r["input"]: r for r in lines}


def hidden(folder: Path) -> list[str]:
    """Hidden files and folders anywhere under `folder`: temporary conversions, partial writes."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*"))


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    return {"ros1": write_ros1_bag(root / "legs.bag", "/scan"), "ros2": write_ros2_bag(root / "lab", "/base_scan")}


@pytest.fixture
def conversions(monkeypatch) -> list[Path]:
    """Every bag opened for conversion in this process (a task of a -j 1 run runs here)."""
    opened: list[Path] = []
    real = importers.open_import

    def counted(path, *args, **kwargs):
        opened.append(Path(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(importers, "open_import", counted)
    return opened


def test_a_bag_done_is_skipped_without_converting_it(tmp_path, bags, conversions):
    out = tmp_path / "out"
    first = invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "1")
    assert first.exit_code == 0, first.output
    assert conversions == [bags["ros1"], bags["ros2"]]
    rec = latest(out)
    assert sorted(rec) == sorted(str(b) for b in bags.values())  # keyed by the bags, not temporary copies
    assert all(r["status"] == "done" and r["scans"] == N_SCANS for r in rec.values())
    assert {Path(r["output"]).name for r in rec.values()} == {"legs.mcap", "lab.mcap"}
    assert hidden(out) == []

    again = invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "1")
    assert again.exit_code == 0, again.output
    assert conversions == [bags["ros1"], bags["ros2"]]  # nothing converted the second time
    assert {r["status"] for r in latest(out).values()} == {"skipped"}
    assert hidden(out) == []


def test_the_output_names_the_bag_with_its_sha256(tmp_path, bags):
    out = tmp_path / "out"
    assert invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "1").exit_code == 0
    for bag, name in ((bags["ros1"], "legs.mcap"), (bags["ros2"], "lab.mcap")):
        sha = mcapio.sha256_of(bag)
        meta = mcapio.summary(out / name).metadata
        assert meta["datmo.inputs"] == {str(bag): sha}
        assert meta["datmo"]["command"] == "run"
        assert latest(out)[str(bag)]["input_sha256"] == sha


def test_a_db3_is_its_bag_folder(tmp_path, bags, conversions):
    out = tmp_path / "out"
    assert invoke(bags["ros2"], "-o", out, "-j", "1").exit_code == 0
    db3 = next(bags["ros2"].glob("*.db3"))
    again = invoke(db3, "-o", out, "-j", "1")
    assert again.exit_code == 0, again.output
    assert list(latest(out)) == [str(bags["ros2"])] and latest(out)[str(bags["ros2"])]["status"] == "skipped"
    assert conversions == [bags["ros2"]]


def test_another_topic_or_force_redoes_a_bag(tmp_path, bags, conversions):
    out = tmp_path / "out"
    bag = str(bags["ros2"])
    assert invoke(bag, "-o", out, "-j", "1").exit_code == 0
    plain = latest(out)[bag]["params_hash"]
    topic = invoke(bag, "-o", out, "-j", "1", "--topic", "/base_scan")
    assert topic.exit_code == 0, topic.output
    assert latest(out)[bag]["status"] == "done" and latest(out)[bag]["params_hash"] != plain
    assert len(conversions) == 2
    same = invoke(bag, "-o", out, "-j", "1", "--topic", "/base_scan")
    assert same.exit_code == 0 and latest(out)[bag]["status"] == "skipped" and len(conversions) == 2
    forced = invoke(bag, "-o", out, "-j", "1", "--topic", "/base_scan", "--force")
    assert forced.exit_code == 0, forced.output
    assert latest(out)[bag]["status"] == "done" and len(conversions) == 3
    assert hidden(out) == []


def test_a_changed_bag_is_redone(tmp_path, bags, conversions):
    bag = write_ros2_bag(tmp_path / "lab", "/base_scan")
    out = tmp_path / "out"
    assert invoke(bag, "-o", out, "-j", "1").exit_code == 0
    (bag / "notes.txt").write_text("a file added to the bag folder changes its SHA-256\n")
    again = invoke(bag, "-o", out, "-j", "1")
    assert again.exit_code == 0, again.output
    assert latest(out)[str(bag)]["status"] == "done" and len(conversions) == 2
    assert latest(out)[str(bag)]["input_sha256"] == mcapio.sha256_of(bag)


def _failing(name: str, exc: BaseException, bad: Path):
    """importers.`name` failing with `exc` for the bag `bad` (write_import after writing the temporary MCAP
    whole: a conversion that breaks at its very end), and as it is for other inputs."""
    real = getattr(importers, name)

    def call(first, *args, **kwargs):
        path = first if name == "open_import" else first.source
        if Path(path) != bad:
            return real(first, *args, **kwargs)
        if name == "write_import":
            real(first, *args, **kwargs)
        raise exc

    return call


FAULTS = {
    "corrupt bag": None,
    "open: InputError": ("open_import", InputError("no LaserScan topic")),
    "open: OSError": ("open_import", OSError(5, "Input/output error")),
    "write: InputError": ("write_import", InputError("no scans to write")),
    "write: RuntimeError": ("write_import", RuntimeError("boom")),
    "write: OSError": ("write_import", OSError(28, "No space left on device")),
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_a_failing_conversion_fails_its_input_alone(tmp_path, bags, monkeypatch, fault):
    """One line for the bag whose conversion fails, its manifest line "failed", the other input done, and no
    temporary file left; the failed bag is tried again by the next run."""
    bad = tmp_path / "bad.bag"
    if FAULTS[fault] is None:
        bad.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    else:
        shutil.copy(bags["ros1"], bad)
        name, exc = FAULTS[fault]
        monkeypatch.setattr(importers, name, _failing(name, exc, bad))
    out = tmp_path / "out"
    result = invoke(bad, bags["ros2"], "-o", out, "-j", "1")
    errors = [line for line in result.stderr.splitlines() if str(bad) in line]
    rec = latest(out)
    broke = not (
        result.exit_code == 1
        and len(errors) == 1
        and errors[0].startswith(f"datmo: error: {bad}: ")
        and "Traceback" not in result.output
        and rec[str(bad)]["status"] == "failed"
        and rec[str(bags["ros2"])]["status"] == "done"
        and (out / "lab.mcap").exists()
        and not (out / "bad.mcap").exists()
        and hidden(out) == []
    )
    tally("run: bag conversion faults", failed=broke)
    assert not broke, (result.output, rec, hidden(out))
    monkeypatch.undo()
    if FAULTS[fault] is not None:  # the bag itself is fine: the next run does it, and skips the other
        again = invoke(bad, bags["ros2"], "-o", out, "-j", "1")
        assert again.exit_code == 0, again.output
        assert [latest(out)[str(p)]["status"] for p in (bad, bags["ros2"])] == ["done", "skipped"]


def test_ctrl_c_during_a_conversion_leaves_no_temporary_file(tmp_path, bags, monkeypatch):
    real = importers.write_import

    def interrupted(stream, output, **kwargs):
        real(stream, output, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(importers, "write_import", interrupted)
    out = tmp_path / "out"
    result = invoke(bags["ros1"], "-o", out, "-j", "1")
    broke = result.exit_code != 130 or hidden(out) != [] or (out / "legs.mcap").exists()
    tally("run: bag conversion faults", failed=broke)
    assert not broke, (result.exit_code, result.output, hidden(out))


def test_a_bag_dir_output_from_a_bag(tmp_path, bags, conversions):
    out = tmp_path / "out"
    result = invoke(bags["ros1"], "-o", out, "-j", "1", "--bag-dir")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (out / "legs").iterdir()) == ["legs_0.mcap", "metadata.yaml"]
    assert mcapio.summary(out / "legs" / "legs_0.mcap").metadata["datmo.inputs"] == {
        str(bags["ros1"]): mcapio.sha256_of(bags["ros1"])
    }
    assert hidden(out) == []
    assert invoke(bags["ros1"], "-o", out, "-j", "1", "--bag-dir").exit_code == 0
    assert latest(out)[str(bags["ros1"])]["status"] == "skipped" and len(conversions) == 1


def test_a_remote_bag_is_converted_by_its_task(tmp_path, bags, conversions):
    fsspec = pytest.importorskip("fsspec")
    mem = fsspec.filesystem("memory")
    mem.pipe("/datmo-bags/in/legs.bag", bags["ros1"].read_bytes())
    url = "memory://datmo-bags/in/legs.bag"
    out = tmp_path / "out"
    try:
        result = invoke(url, "-o", out, "-j", "1")
        assert result.exit_code == 0, result.output
        assert mcapio.summary(out / "legs.mcap").metadata["datmo.inputs"] == {url: mcapio.sha256_of(bags["ros1"])}
        assert invoke(url, "-o", out, "-j", "1").exit_code == 0
        assert latest(out)[url]["status"] == "skipped" and len(conversions) == 1
    finally:
        mem.rm("/datmo-bags", recursive=True)
    assert hidden(out) == []


def test_local_processes_convert_their_own_bags(tmp_path, bags):
    """--jobs 2: each bag converted in its worker process, which says so through its record (the command
    prints it, above the bar: a forked worker's own stderr is not this one); a rerun in one process skips both."""
    out = tmp_path / "out"
    result = invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "2", quiet=False)
    assert result.exit_code == 0, result.output
    assert {r["status"] for r in latest(out).values()} == {"done"} and hidden(out) == []
    for bag in bags.values():
        said = [line for line in result.stderr.splitlines() if line.startswith(f"datmo: converted {bag} ")]
        assert len(said) == 1 and said == latest(out)[str(bag)]["notes"]
    again = invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "1")
    assert again.exit_code == 0 and {r["status"] for r in latest(out).values()} == {"skipped"}


@pytest.mark.slow
def test_dask_workers_convert_their_own_bags(tmp_path, bags):
    pytest.importorskip("distributed")
    import subprocess
    import sys

    out = tmp_path / "out"
    # in a process of its own: a local Dask cluster sets NUMBA_NUM_THREADS=1 in this process's environment while
    # it spawns its workers, and numba's thread pool must not start here under that setting (as test_cluster.py)
    datmo = Path(sys.executable).with_name("datmo")
    result = subprocess.run(
        [str(datmo), "run", str(bags["ros1"]), str(bags["ros2"]), "-o", str(out), "--scheduler", "local:2", "-q"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    rec = latest(out)
    assert {r["status"] for r in rec.values()} == {"done"} and hidden(out) == []
    assert mcapio.summary(out / "lab.mcap").metadata["datmo.inputs"] == {
        str(bags["ros2"]): mcapio.sha256_of(bags["ros2"])
    }
    again = invoke(bags["ros1"], bags["ros2"], "-o", out, "-j", "1")
    assert again.exit_code == 0 and {r["status"] for r in latest(out).values()} == {"skipped"}
