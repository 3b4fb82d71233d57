"""The datmo_msgs ROS 2 package, outputs as ROS 2 bag folders (--bag-dir), and the QoS written.

The package in datmo_msgs/ must be buildable by colcon (package.xml, CMakeLists.txt listing every .msg with its
dependencies) and hold the same .msg files the Python package reads (datmo_cli/msg, the source). colcon cannot
run here, so the .msg files are checked with rosbags' parser and against rosidl's naming rules. A bag folder is
opened with rosbags' ROS 2 reader and every message deserialised with the types of datmo_msgs/msg.
"""

from __future__ import annotations

import errno
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli import __version__
from datmo_cli.base import outputs
from datmo_cli.cli import cli
from datmo_cli.logs import bagdir, mcapio
from datmo_cli.logs.scan import ScanRun

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "datmo_msgs"
SOURCE = ROOT / "datmo_cli" / "msg"
HALL = ROOT / "sample_logs" / "hall.mcap"
RESYNC = "cp datmo_cli/msg/*.msg datmo_msgs/msg/"

PRIMITIVES = {
    "bool",
    "byte",
    "char",
    "float32",
    "float64",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "string",
    "wstring",
}
# rosidl_adapter's rules (msg names PascalCase; fields lower_case without '__' or a trailing '_'; constants
# UPPER_CASE), and names the generated C++ and Python code cannot take.
MSG_NAME = re.compile(r"^[A-Z][A-Za-z0-9]*$")
FIELD_NAME = re.compile(r"^(?!.*__)(?!.*_$)[a-z][a-z0-9_]*$")
CONSTANT_NAME = re.compile(r"^[A-Z]([A-Z0-9_]?[A-Z0-9]+)*$")
PACKAGE_NAME = re.compile(r"^(?!.*__)(?!.*_$)[a-z][a-z0-9_]*$")
RESERVED = {
    "and",
    "as",
    "assert",
    "async",
    "await",
    "break",
    "class",
    "continue",
    "def",
    "del",
    "elif",
    "else",
    "except",
    "finally",
    "for",
    "from",
    "global",
    "if",
    "import",
    "in",
    "is",
    "lambda",
    "nonlocal",
    "not",
    "or",
    "pass",
    "raise",
    "return",
    "try",
    "while",
    "with",
    "yield",
    "auto",
    "bool",
    "case",
    "char",
    "const",
    "default",
    "delete",
    "double",
    "enum",
    "float",
    "int",
    "long",
    "namespace",
    "new",
    "operator",
    "private",
    "public",
    "short",
    "signed",
    "sizeof",
    "static",
    "struct",
    "switch",
    "template",
    "this",
    "throw",
    "typedef",
    "union",
    "unsigned",
    "virtual",
    "void",
    "volatile",
}


def msg_files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.msg"))}


def rosidl_problems(name: str, text: str, known: set[str]) -> list[str]:
    """What rosidl would refuse in the .msg `name` (e.g. "Track") with body `text`; `known`: the message types
    that exist ("pkg/Name")."""
    problems = [] if MSG_NAME.match(name) else [f"{name}: message name not PascalCase"]
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        kind, rest = line.split(None, 1) if " " in line else (line, "")
        base = re.sub(r"\[[0-9<=]*\]$", "", kind)
        if "=" in rest:
            const = rest.split("=", 1)[0].strip()
            if not CONSTANT_NAME.match(const):
                problems.append(f"{name}:{n}: constant {const!r} not UPPER_CASE")
            if base not in PRIMITIVES or base != kind:
                problems.append(f"{name}:{n}: constant {const!r} of a non-primitive type {kind!r}")
            continue
        field = rest.split()[0] if rest else ""
        if not FIELD_NAME.match(field) or field in RESERVED:
            problems.append(f"{name}:{n}: field name {field!r} not lower_case or reserved")
        if base in PRIMITIVES or base == "Header":
            continue
        pkg, _, typ = base.rpartition("/")
        if not pkg or not PACKAGE_NAME.match(pkg) or not MSG_NAME.match(typ) or f"{pkg}/{typ}" not in known:
            problems.append(f"{name}:{n}: unknown type {kind!r}")
    return problems


def referenced_packages() -> set[str]:
    pkgs = set()
    for text in msg_files(SOURCE).values():
        for raw in text.decode().splitlines():
            line = raw.split("#", 1)[0].split()
            if line and "/" in line[0]:
                pkgs.add(line[0].split("/")[0])
    return pkgs - {"datmo_msgs"}


def datmo_msgs_store():
    """A Humble type store with the types of datmo_msgs/msg (the ROS package's copies) registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, data in msg_files(PACKAGE / "msg").items():
        types.update(get_types_from_msg(data.decode(), f"datmo_msgs/msg/{name[:-4]}"))
    store.register(types)
    return store


# ------------------------------------------------------------------------------------------- the package


def test_msg_files_are_the_python_packages_byte_for_byte():
    ours, theirs = msg_files(SOURCE), msg_files(PACKAGE / "msg")
    assert ours, "no .msg files in datmo_cli/msg"
    assert sorted(theirs) == sorted(ours), f"datmo_msgs/msg holds other files than datmo_cli/msg; run: {RESYNC}"
    differ = [n for n in ours if ours[n] != theirs[n]]
    assert not differ, f"{differ} differ between datmo_cli/msg (the source) and datmo_msgs/msg; run: {RESYNC}"


def test_cmakelists_generates_every_msg_with_its_dependencies():
    text = (PACKAGE / "CMakeLists.txt").read_text()
    block = re.search(r"rosidl_generate_interfaces\(\$\{PROJECT_NAME\}(.*?)\)", text, re.S).group(1)
    listed, _, deps = block.partition("DEPENDENCIES")
    assert sorted(re.findall(r'"msg/([A-Za-z0-9]+\.msg)"', listed)) == sorted(msg_files(SOURCE))
    assert set(deps.split()) == referenced_packages() == {"std_msgs", "builtin_interfaces"}
    assert re.search(r"project\(datmo_msgs\)", text)
    for pkg in ("ament_cmake", "rosidl_default_generators", *referenced_packages()):
        assert f"find_package({pkg} REQUIRED)" in text
    assert "ament_export_dependencies(rosidl_default_runtime)" in text and "ament_package()" in text


def test_package_xml_is_a_format_3_interface_package():
    root = ET.parse(PACKAGE / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "datmo_msgs" and root.findtext("version") == __version__
    assert root.find("maintainer").get("email") and root.findtext("license") and root.findtext("description")
    tags = {(e.tag, e.text) for e in root}
    assert {
        ("buildtool_depend", "ament_cmake"),
        ("buildtool_depend", "rosidl_default_generators"),
        ("exec_depend", "rosidl_default_runtime"),
        ("member_of_group", "rosidl_interface_packages"),
    } <= tags
    assert {t for kind, t in tags if kind == "depend"} == referenced_packages()
    assert root.find("export").findtext("build_type") == "ament_cmake"


def test_msg_files_parse_and_follow_rosidl_rules():
    store = datmo_msgs_store()
    known = {name.replace("/msg/", "/") for name in store.fielddefs}
    problems = []
    for name, data in msg_files(PACKAGE / "msg").items():
        problems += rosidl_problems(name[:-4], data.decode(), known)
    assert not problems
    for name in msg_files(PACKAGE / "msg"):
        for _, (node, spec) in store.fielddefs[f"datmo_msgs/msg/{name[:-4]}"][1]:
            inner = spec[0] if node in (3, 4) else (node, spec)
            if inner[0] == 2:  # a named type: the store knows it
                assert inner[1] in store.fielddefs, (name, inner)


@pytest.mark.parametrize(
    "line, what",
    [
        ("float32 myField", "field name"),
        ("float32 x__y", "field name"),
        ("float32 x_", "field name"),
        ("uint8 class", "field name"),
        ("uint8 Lower=1", "constant"),
        ("uint8[2] FOO=1", "non-primitive"),
        ("foo_msgs/Bar bar", "unknown type"),
        ("datmo_msgs/NoSuch x", "unknown type"),
        ("Float33 x", "unknown type"),
    ],
)
def test_the_rosidl_checker_catches_what_rosidl_refuses(line, what):
    problems = rosidl_problems("Good", f"# a comment\n{line}\n", {"datmo_msgs/Track"})
    assert len(problems) == 1 and what in problems[0], problems
    assert rosidl_problems("bad_name", "uint8 x\n", set())[0].startswith("bad_name: message name")


# ----------------------------------------------------------------------------------------------- the QoS


def test_qos_written_is_reliable_and_volatile_as_rosbag2_records_a_topic():
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2.metadata import parse_qos

    (qos,) = parse_qos(mcapio.QOS_YAML)
    assert (qos.reliability, qos.durability) == (QosReliability.RELIABLE, QosDurability.VOLATILE)
    (latched,) = parse_qos(mcapio.QOS_YAML_LATCHED)
    assert (latched.reliability, latched.durability) == (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)
    assert latched._replace(durability=qos.durability) == qos


# ------------------------------------------------------------------------------------------- bag folders


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The first 30 scans of the hall sample log."""
    run = mcapio.read_run(HALL)
    run = ScanRun(run.stamps[:30], run.ranges[:30], run.geometry, None)
    path = tmp_path_factory.mktemp("in") / "small.mcap"
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
    return path


def datmo(*args) -> object:
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(res, *needles: str) -> None:
    assert res.exit_code != 0 and "Traceback" not in res.output, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: "), res.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def hidden(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def check_bag(folder: Path) -> dict[str, int]:
    """Open `folder` with rosbags' ROS 2 reader, deserialise every message with datmo_msgs' types; the counts
    per topic agree with the metadata and with the MCAP file itself. Returns them."""
    from rosbags.rosbag2 import Reader
    from ruamel.yaml import YAML

    assert sorted(p.name for p in folder.iterdir()) == sorted([bagdir.member(folder).name, "metadata.yaml"])
    info = YAML(typ="safe").load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == bagdir.VERSION and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == [bagdir.member(folder).name]
    store = datmo_msgs_store()
    counts: dict[str, int] = {}
    with Reader(folder) as reader:
        assert reader.message_count == info["message_count"] == sum(c.msgcount for c in reader.connections)
        for conn, stamp, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            if hasattr(msg, "header"):
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec <= stamp + 10**9
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
        assert counts == {c.topic: c.msgcount for c in reader.connections}
        assert reader.start_time == info["starting_time"]["nanoseconds_since_epoch"]
    summary = mcapio.summary(bagdir.member(folder))
    assert counts == {c.topic: c.count for c in summary.channels.values()}
    assert {
        t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
        for t in info["topics_with_message_count"]
    } == {c.topic: c.metadata["offered_qos_profiles"] for c in summary.channels.values()}
    return counts


def test_track_bag_dir_is_read_by_rosbags_ros2_reader(small, tmp_path):
    res = datmo("track", small, "-o", f"{tmp_path}/tracked/", "--bag-dir")
    assert res.exit_code == 0, res.output
    counts = check_bag(tmp_path / "tracked")
    assert counts["/scan"] == counts["/datmo/tracks"] == counts["/datmo/features"] == 30
    assert hidden(tmp_path) == []


def test_run_bag_dir_writes_one_bag_per_input_and_resumes(small, tmp_path):
    other = tmp_path / "in" / "other.mcap"
    other.parent.mkdir()
    other.write_bytes(small.read_bytes())
    out = tmp_path / "out"
    res = datmo("run", small, other, "-o", out, "--bag-dir", "--plot", "--no-report")
    assert res.exit_code == 0, res.output
    for name in ("small", "other"):
        assert check_bag(out / name)["/datmo/tracks"] == 30
        assert (out / f"{name}.png").is_file()
    from datmo_cli.batch import read_batch

    assert sorted(r["output"] for r in read_batch(str(out))) == sorted(
        str(out / n / f"{n}_0.mcap") for n in ("small", "other")
    )
    before = (out / "small" / "small_0.mcap").stat().st_mtime_ns
    again = datmo("run", small, "-o", out, "--bag-dir", "--no-report")
    assert again.exit_code == 0 and "1 skipped" in again.stderr, again.output
    forced = datmo("run", small, "-o", out, "--bag-dir", "--no-report", "--force")
    assert forced.exit_code == 0, forced.output
    assert (out / "small" / "small_0.mcap").stat().st_mtime_ns != before
    check_bag(out / "small")
    assert not [n for n in hidden(out) if n.endswith(".tmp")]


def test_bag_dir_replaces_only_a_bag_and_only_with_force(small, tmp_path):
    bag = tmp_path / "bag"
    assert datmo("track", small, "-o", bag, "--bag-dir").exit_code == 0
    first = (bag / "bag_0.mcap").read_bytes()
    one_line_error(datmo("track", small, "-o", bag, "--bag-dir"), f"{bag}: exists; use --force")
    assert (bag / "bag_0.mcap").read_bytes() == first
    res = datmo("track", small, "-o", bag, "--bag-dir", "--force", "--no-markers")
    assert res.exit_code == 0, res.output
    assert "/datmo/markers/tracks" not in check_bag(bag)

    one_line_error(datmo("track", bag / "bag_0.mcap", "-o", bag, "--bag-dir", "--force"), "replace the input")
    (bag / "notes.txt").write_text("mine")  # no longer only a bag: never replaced
    one_line_error(datmo("track", small, "-o", bag, "--bag-dir", "--force"), "not a ROS 2 bag", "never replaced")
    assert (bag / "notes.txt").read_text() == "mine"
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    one_line_error(datmo("track", small, "-o", plain, "--bag-dir", "--force"), "not a folder")
    one_line_error(datmo("track", small, "-o", tmp_path / "x.mcap", "--bag-dir"), "name it without .mcap")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert datmo("track", small, "-o", empty, "--bag-dir").exit_code == 0  # an empty folder holds nothing to lose
    check_bag(empty)
    assert hidden(tmp_path) == []


def test_a_failed_bag_leaves_no_temporary_folder_and_the_old_bag_intact(small, tmp_path, monkeypatch):
    from fuzzing import tally
    from test_fault_injection import ROOM, FullDisk

    bag = tmp_path / "bag"
    assert datmo("track", small, "-o", bag, "--bag-dir").exit_code == 0
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    real = outputs._file_for

    def metadata_fails(log, name):
        raise OSError(errno.ENOSPC, "No space left on device")

    cases = [("room", room) for room in ROOM[:4]] + [("metadata", None)]
    for i, (kind, room) in enumerate(cases):
        if kind == "room":
            monkeypatch.setattr(outputs, "_file_for", lambda fd, mode, room=room: FullDisk(real(fd, mode), room))
        else:
            monkeypatch.setattr(bagdir, "metadata_text", metadata_fails)
        for target in (bag, tmp_path / f"new{i}"):
            res = datmo("track", small, "-o", target, "--bag-dir", "--force")
            last = res.stderr.strip().splitlines()[-1] if res.stderr.strip() else ""
            ok = res.exit_code == 1 and last == f"datmo: error: {target}: no space left on the device (writing it)"
            ok = ok and hidden(tmp_path) == [] and not (tmp_path / f"new{i}").exists() and not outputs.live()
            ok = ok and {p.name: p.read_bytes() for p in bag.iterdir()} == before
            tally("bag folder write failures", failed=not ok)
            assert ok, (kind, room, target, res.output)
        monkeypatch.undo()
