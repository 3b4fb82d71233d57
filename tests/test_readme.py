"""The README runs, and so do the guide pages its long sections moved to: every ```sh and ```python block of
README.md and of each page of GUIDE, in that order, in one fresh folder, as a user would after `make demo`.

The folder holds a copy of `sample_logs/` and the demo's outputs (`out/`, made first with the Makefile's demo
command), and sits beside a `shared` link to ../shared, so `../shared/data/...` resolves as in a clone beside
CI's data. The README's conventions for lines that are not run (it states them under its first block):
- a block whose first line is a comment `# needs ...` (ROS 2, a Dask cluster) is not run;
- a line ending in a comment `# needs ...` (an LMS200 on /dev/ttyUSB0) is not run;
- `make` lines are not run: the demo's command has run already, and `make test` would run this test again.
`datmo emulate` runs in the background until its block ends, then gets Ctrl-C and must exit 130; the device
path it prints replaces the README's example path (`/dev/pts/N`) in that block's later lines. Every other
line must exit 0 without a traceback. Lines not run are printed with their reason; the counts go to the
"README commands" tallies of the run's summary. A ```python block runs whole, with the venv's Python, in the same
folder. docs/export.md, docs/python.md, docs/method.md and docs/lms2xx.md run in tests/test_docs.py instead, and
tests/test_docs.py checks that every page of docs/ is run by one of the two.
"""

from __future__ import annotations

import os
import re
import selectors
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
from conftest import ROOT, SAMPLE_LOGS, SHARED_DATA, shared_path
from fuzzing import tally

pytestmark = pytest.mark.cli

README = ROOT / "README.md"
DOCS = ROOT / "docs"
# README.md and the pages its sections moved to, in the order their examples build on each other's outputs
GUIDE = [
    README,
    *(
        DOCS / name
        for name in (
            "package-page.md",
            "install.md",
            "import.md",
            "simulate.md",
            "record.md",
            "processing.md",
            "ros2.md",
            "legs.md",
            "report.md",
            "batch.md",
            "performance.md",
            "reliability.md",
            "architecture.md",
        )
    ),
]
MAKEFILE = ROOT / "Makefile"
NEEDS = re.compile(r"(?:^|\s)#\s*(needs\b.*)$")  # the README's marker: a comment starting "needs"
HEREDOC = re.compile(r"<<-?\s*['\"]?(\w+)['\"]?")  # cat > FILE <<'EOF' ... EOF
OUTPUT = re.compile(r"(?:\s-o\s+|\s>\s*)([^\s;|&<>]+)")  # -o PATH, > PATH
EXAMPLE_PTY = re.compile(r"/dev/pts/\d+")
COMMAND_TIMEOUT = 600  # s, a hung command fails the test instead of hanging it
EMULATE_START_TIMEOUT = 60  # s to print its device path


def example_blocks(text: str, languages: tuple[str, ...] = ("sh", "python")) -> list[tuple[str, list[str]]]:
    """(language, lines) of every fenced block in `languages`, in order (only top-level fences: indented ones are
    quoted data)."""
    blocks, block, language = [], None, None
    for line in text.splitlines():
        fence = line.rstrip()
        if block is None and fence.startswith("```") and fence[3:] in languages:
            block, language = [], fence[3:]
        elif block is not None and fence == "```":
            blocks.append((language, block))
            block = None
        elif block is not None:
            block.append(line)
    assert block is None, f"a ```{language} block is not closed"
    return blocks


def sh_blocks(text: str) -> list[list[str]]:
    """The lines of every ```sh fenced block, in order."""
    return [lines for _, lines in example_blocks(text, ("sh",))]


def logical_lines(block: list[str]) -> list[str]:
    """The block's shell commands: continued lines joined, a here-document kept with its command."""
    out, pending, end = [], "", None
    for line in block:
        if end is not None:
            pending += "\n" + line
            if line.strip() == end:
                out.append(pending)
                pending, end = "", None
            continue
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        pending += line
        heredoc = HEREDOC.search(line)
        if heredoc:
            end = heredoc.group(1)
            continue
        out.append(pending)
        pending = ""
    assert end is None and not pending, f"README.md: a block ends inside a command: {pending!r}"
    return out


def commands(block: list[str]) -> list[tuple[str, str | None]]:
    """The block's commands (continued lines joined), each with the reason it is not run, or None."""
    first = next((line.strip() for line in block if line.strip()), "")
    block_reason = NEEDS.search(first).group(1) if first.startswith("#") and NEEDS.search(first) else None
    out = []
    for line in logical_lines(block):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        marker = NEEDS.search(stripped)
        if block_reason:
            out.append((stripped, block_reason))
        elif marker:
            out.append((stripped, marker.group(1)))
        elif stripped.startswith("make "):
            out.append((stripped, "a make target: the demo's command has run; make test would run this test again"))
        else:
            out.append((stripped, None))
    return out


def demo_command() -> str:
    """The Makefile's `demo` recipe as a user's shell runs it (datmo on PATH)."""
    text = MAKEFILE.read_text()
    demo_log = re.search(r"^DEMO_LOG\s*:=\s*(\S+)", text, re.M).group(1)
    recipe = re.search(r"^demo:.*\n\t(.+)$", text, re.M).group(1)
    return recipe.replace("$(BIN)/", "").replace("$(DEMO_LOG)", demo_log)


def run(command: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    """Run one README command with bash in `cwd`."""
    return subprocess.run(
        ["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=COMMAND_TIMEOUT
    )


def start_emulator(command: str, cwd: Path, env: dict[str, str]) -> tuple[subprocess.Popen, str]:
    """Start `datmo emulate` in the background; return it and the device path it prints on its first line."""
    proc = subprocess.Popen(
        ["bash", "-c", "exec " + command], cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    if not sel.select(EMULATE_START_TIMEOUT):
        proc.kill()
        pytest.fail(f"{command}: printed no device path in {EMULATE_START_TIMEOUT} s")
    device = proc.stdout.readline().strip()
    if not device.startswith("/dev/"):
        proc.kill()
        pytest.fail(f"{command}: first line {device!r} is not a device path; stderr: {proc.stderr.read()}")
    return proc, device


def stop_emulator(proc: subprocess.Popen, command: str) -> str | None:
    """Ctrl-C the emulator; a problem as one line, or None when it exits 130 as documented."""
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        return f"{command}: still running 30 s after Ctrl-C"
    if proc.returncode != 130:
        return f"{command}: exit {proc.returncode} after Ctrl-C (documented: 130); stderr: {err.strip()}"
    return None


def outputs(command: str) -> list[str]:
    """The files a command names as its outputs: `-o PATH` (not `-`) and `> PATH` redirections."""
    first_line = command.split("\n", 1)[0]
    return [path for path in OUTPUT.findall(first_line) if path != "-"]


def problem(command: str, result: subprocess.CompletedProcess, cwd: Path) -> str | None:
    """Why a README command's run breaks the README's promise, or None."""
    if result.returncode != 0:
        tail = (result.stderr.strip() or result.stdout.strip())[-2000:]
        return f"{command}: exit {result.returncode}: {tail}"
    if "Traceback" in result.stderr:
        return f"{command}: a traceback on stderr: {result.stderr.strip()[-2000:]}"
    empty = [path for path in outputs(command) if not (cwd / path).exists() or (cwd / path).stat().st_size == 0]
    if empty:
        return f"{command}: exit 0 but no output or an empty one: {', '.join(empty)}"
    return None


def run_python(block: list[str], where: str, cwd: Path, env: dict[str, str]) -> str | None:
    """Run a ```python block whole with the venv's Python in `cwd`; why it fails, or None."""
    code = "\n".join(block)
    start = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=COMMAND_TIMEOUT
    )
    print(f"  {time.monotonic() - start:6.1f} s  ({where}: a python block)")
    why = problem(f"{where}: the python block starting {block[0]!r}", result, cwd)
    tally("README commands", failed=why is not None)
    return why


def run_block(block: list[str], cwd: Path, env: dict[str, str]) -> tuple[int, list[str], list[tuple[str, str]]]:
    """Run one README block's commands in order: (commands run, failures, (command, reason) of those not run)."""
    ran, failures, skipped, emulator = 0, [], [], None
    try:
        for command, reason in commands(block):
            if reason:
                skipped.append((command, reason))
                tally("README commands not run (marked)")
                continue
            if emulator is not None:
                command = EXAMPLE_PTY.sub(emulator[1], command)
            ran += 1
            if command.startswith("datmo emulate "):
                emulator = (*start_emulator(command, cwd, env), command)
                continue
            start = time.monotonic()
            why = problem(command, run(command, cwd, env), cwd)
            print(f"  {time.monotonic() - start:6.1f} s  {command}")
            tally("README commands", failed=why is not None)
            failures += [why] if why else []
        if emulator is not None:  # counted here: its exit after Ctrl-C is part of its promise
            why = stop_emulator(emulator[0], emulator[2])
            tally("README commands", failed=why is not None)
            failures += [why] if why else []
    finally:
        if emulator is not None and emulator[0].poll() is None:  # a command of its block raised
            emulator[0].kill()
            emulator[0].wait()
    return ran, failures, skipped


def test_sh_blocks_and_markers():
    """The extraction itself: continued lines join, markers skip a block or a line, make lines are skipped."""
    text = "\n".join(
        [
            "```sh",
            "make demo    # a comment",
            "datmo a \\",
            "    --b c",
            "datmo d   # needs an LMS200",
            "```",
            "  ```sh",
            "  indented: quoted data",
            "  ```",
            "```toml",
            "x = 1",
            "```",
            "```sh",
            "# needs ROS 2",
            "ros2 bag play x",
            "```",
            "```sh",
            "cat > a.toml <<'EOF'",
            "# not a comment line here",
            "x = 1",
            "EOF",
            "datmo e",
            "```",
        ]
    )
    blocks = sh_blocks(text)
    assert len(blocks) == 3
    first, second, third = (commands(block) for block in blocks)
    assert [c for c, _ in first] == ["make demo    # a comment", "datmo a      --b c", "datmo d   # needs an LMS200"]
    assert first[0][1].startswith("a make target") and first[1][1] is None and first[2][1] == "needs an LMS200"
    assert second == [("ros2 bag play x", "needs ROS 2")]
    assert third == [("cat > a.toml <<'EOF'\n# not a comment line here\nx = 1\nEOF", None), ("datmo e", None)]
    assert demo_command().startswith("datmo run sample_logs/")


def test_outputs_named():
    """The outputs a command names, whose absence or emptiness fails it."""
    assert outputs("datmo run a.mcap -o out-all --plot") == ["out-all"]
    assert outputs("datmo config --no-config > my-params.toml   # a comment") == ["my-params.toml"]
    assert outputs("datmo export x.mcap -o - --format ndjson | head -3") == []
    assert outputs("cat > my_room.toml <<'EOF'\nname = 'x' > y\nEOF") == ["my_room.toml"]


def test_readme_config_example(tmp_path):
    """The example datmo.toml (the ```toml block of the README's guide pages: docs/processing.md) is a config datmo
    takes every key of."""
    blocks = [block for page in GUIDE for block in re.findall(r"^```toml\n(.*?)^```", page.read_text(), re.M | re.S)]
    assert blocks, "no ```toml example in the README or its guide pages"
    for block in blocks:
        (tmp_path / "datmo.toml").write_text(block)
        result = subprocess.run(
            [str(Path(sys.executable).with_name("datmo")), "config"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert result.returncode == 0, result.stderr
        keys = [key for table in tomllib.loads(block).values() for key in table]
        taken = [key for key in keys if re.search(rf"^{key} = .*# from datmo\.toml", result.stdout, re.M)]
        assert taken == keys, f"keys of the README's datmo.toml not taken from it: {set(keys) - set(taken)}"


def test_readme_fences_are_sh():
    """Shell examples use ```sh fences only (no ```bash, ```shell or ```console) and Python ones ```python (no
    ```py): the tests that run them see them all. Every page of docs/ and CONTRIBUTING.md too."""
    for page in [*GUIDE, *sorted(DOCS.glob("*.md")), ROOT / "CONTRIBUTING.md"]:
        fences = re.findall(r"^```(\w+)", page.read_text(), re.M)
        assert not {"bash", "shell", "console", "zsh", "py", "python3"} & set(fences), (page.name, fences)


@pytest.mark.slow
@pytest.mark.shared
def test_readme_runs(tmp_path):
    """Every command of the README and its guide pages not marked otherwise exits 0, in order, in a fresh folder
    after the demo; so does every python block there."""
    shared_path()  # the README reads ../shared/data: skip where absent, fail under CI=true
    (tmp_path / "shared").symlink_to(SHARED_DATA.parent, target_is_directory=True)
    work = tmp_path / "datmo"
    work.mkdir()
    shutil.copytree(SAMPLE_LOGS, work / "sample_logs")
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.pop("DATMO_DEBUG", None)

    demo = demo_command()
    why = problem(demo, run(demo, work, env), work)
    assert why is None, why
    assert list((work / "out").glob("*.png")), f"{demo}: no plot in out/ (the README says make demo draws one)"

    failures, ran, skipped = [], 0, []
    print()
    for page in GUIDE:
        where = page.relative_to(ROOT).as_posix()
        print(where)
        for language, block in example_blocks(page.read_text()):
            if language == "python":
                why = run_python(block, where, work, env)
                ran, failures = ran + 1, failures + ([why] if why else [])
                continue
            block_ran, block_failures, block_skipped = run_block(block, work, env)
            ran, failures, skipped = ran + block_ran, failures + block_failures, skipped + block_skipped
    print(f"README and its guide pages: {ran} commands run, {len(skipped)} not run:")
    for command, reason in skipped:
        print(f"  not run ({reason}): {command}")
    assert ran > 0
    assert not failures, "README and guide commands that fail as written:\n" + "\n".join(failures)
