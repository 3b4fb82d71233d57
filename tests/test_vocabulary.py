"""The message vocabulary: log.vocabulary's codes are the .msg files' constants (read here from the text
and from rosbags' type store), its name tables are the ones the outputs print, and no other module of the
package declares them again."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import datmo_cli
from datmo_cli.logs import types, vocabulary

pytestmark = pytest.mark.unit

PACKAGE = Path(datmo_cli.__file__).parent
CONSTANT = re.compile(r"^\s*\w+\s+([A-Z][A-Z0-9_]*)\s*=\s*(-?\d+)", re.MULTILINE)
# how vocabulary names each file's constants: the .msg name with this prefix
PREFIX = {"Track": "", "GroundTruthObject": "", "Landmark": "LANDMARK_", "Blob": "BLOB_"}


def msg_constants() -> dict[str, dict[str, int]]:
    """{file stem: {name: value}} of every .msg file under datmo_cli/msg with constants, from its text."""
    out = {}
    for path in sorted((PACKAGE / "msg").glob("*.msg")):
        found = {name: int(value) for name, value in CONSTANT.findall(path.read_text(encoding="utf-8"))}
        if found:
            out[path.stem] = found
    return out


def vocabulary_constants() -> dict[str, int]:
    return {k: v for k, v in vars(vocabulary).items() if k.isupper() and not k.startswith("_") and type(v) is int}


def test_every_msg_constant_is_in_the_vocabulary_with_the_files_value():
    consts = msg_constants()
    assert set(consts) == set(PREFIX)
    for stem, table in consts.items():
        for name, value in table.items():
            assert getattr(vocabulary, PREFIX[stem] + name) == value, (stem, name)
            assert type(getattr(vocabulary, PREFIX[stem] + name)) is int  # a numba compile-time constant


def test_every_vocabulary_constant_comes_from_a_msg_file():
    named = {PREFIX[stem] + name: value for stem, table in msg_constants().items() for name, value in table.items()}
    assert vocabulary_constants() == named


def test_the_constants_are_the_type_stores():
    store = types.typestore()
    for stem in PREFIX:
        msgtype = f"datmo_msgs/msg/{stem}"
        cls = store.types[msgtype]
        assert types.constants(msgtype) == {k: getattr(cls, k) for k in msg_constants()[stem]}, stem


def test_the_name_tables_are_what_the_outputs_print():
    assert vocabulary.CLASS_NAMES == {0: "unknown", 1: "person", 2: "circle object", 3: "rectangular object"}
    assert vocabulary.MOBILITY_NAMES == {0: "static", 1: "dynamic", 2: "undefined"}
    assert vocabulary.STATUS_NAMES == {0: "tentative", 1: "confirmed", 2: "coasting"}
    assert vocabulary.LANDMARK_NAMES == {
        0: "corner",
        1: "convex deflection",
        2: "concave deflection",
        3: "line end",
        4: "column",
        5: "bench",
    }
    assert vocabulary.BLOB_KIND_NAMES == {0: "blob", 1: "point"}


# Names that would declare the vocabulary again: its own, the .msg files' bare ones (CORNER, ...), the
# class and mobility codes without their prefix (PERSON, DYNAMIC, ...), and the tables and short forms once
# used (not STATUS_*'s bare names: tracking.state names its columns CONFIRMED, ...).
FORBIDDEN = (
    {
        *vocabulary_constants(),
        "CLASS_NAMES",
        "MOBILITY_NAMES",
        "STATUS_NAMES",
        "LANDMARK_NAMES",
        "BLOB_KIND_NAMES",
        "TYPE_NAMES",
        "CLASS_CIRCLE",
        "CLASS_RECT",
        "TRACK_STATIC",
    }
    | set(msg_constants()["Landmark"])
    | {
        k.split("_", 1)[1]
        for stem in ("Track", "GroundTruthObject")
        for k in msg_constants()[stem]
        if not k.startswith("STATUS_")
    }
)
# Modules that still declare Track.msg's codes themselves (the tracking kernels and the classification
# reference), until they are rewritten to take them from log/vocabulary.py.


def assigned_names(tree: ast.AST) -> set[str]:
    """Names bound by assignments anywhere in `tree` (tuple targets included)."""
    out = set()
    for node in ast.walk(tree):
        targets = (
            node.targets
            if isinstance(node, ast.Assign)
            else [node.target]
            if isinstance(node, ast.AnnAssign | ast.AugAssign)
            else []
        )
        for t in targets:
            out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
    return out


def test_no_module_declares_the_vocabulary_again():
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel == "log/vocabulary.py":
            continue
        names = assigned_names(ast.parse(path.read_text(encoding="utf-8"))) & FORBIDDEN
        if names:
            found[rel] = sorted(names)
    assert found == {}


def test_the_scan_finds_a_declaration():
    tree = ast.parse("STATUS_CONFIRMED = 1\nCORNER, COLUMN = 0, 4\ndef f():\n    PERSON = 1\n")
    assert assigned_names(tree) & FORBIDDEN == {"STATUS_CONFIRMED", "CORNER", "COLUMN", "PERSON"}
