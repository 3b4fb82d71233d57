"""The kernels' parameter vectors by name: each [features] and [track] key the kernels read has its slot in one
name table (perception.feature_layout.FEATURE_PARAMS, FP_<KEY>; tracking.state.PARAM_NAMES, P_<KEY>), every slot
is read by a kernel, and every other key is listed below with the file that reads it.

The kernels' reads are found in their source: a slot constant loaded (`p[FP_CIRCLE_CELL]`) in a function of the
package compiled by numba (@njit); an import, or a read in plain Python around the kernels, is no kernel's read."""

from __future__ import annotations

import ast
import math
from dataclasses import fields
from pathlib import Path

import pytest

import datmo_cli
from datmo_cli.perception import feature_layout
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking import state
from datmo_cli.tracking.params import TrackingParams

pytestmark = pytest.mark.unit

PACKAGE = Path(datmo_cli.__file__).parent

# [features] keys that are not in the feature kernels' vector: the file (under datmo_cli/) that reads each, by name
FEATURES_ELSEWHERE = {
    "d_max": "perception/landmarks.py",  # wall lines and line ends (numpy); the tracking vector's d_max too
    "corner_gap": "perception/landmarks.py",  # corners and deflections (numpy)
    "deflection_min": "perception/landmarks.py",
    "theta_resolution": "perception/features.py",  # the HTL's theta cells, passed as their cos/sin tables
    "leg_model": "perception/features.py",  # a string: the leg detector's file, loaded in Python
}

# [track] keys that are not in the tracking kernels' vector, and where they are read
TRACK_ELSEWHERE = {
    "hindsight_lag": "passes/stages.py",  # how long the tracking stage holds scans back (Python)
    "free_space_scans": "tracking/tracker.py",  # sizes the ring of kept scans the kernels are given
    "ego_motion": "passes/pipeline.py",  # a string: which odometry the tracking frame follows
}

# slots after a name table's keys that are no key of its section
TRACK_EXTRA_SLOTS = {"P_LEG_THRESHOLD": state.N_PARAMS}  # the leg model's threshold_p, appended by kernel_vector


def _is_kernel(node: ast.AST) -> bool:
    """A function compiled by numba: decorated with njit or jit (bare, called, or numba.njit)."""
    if not isinstance(node, ast.FunctionDef):
        return False
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def slots_read(folder: str, prefix: str) -> set[str]:
    """Names starting with `prefix` that the numba kernels of datmo_cli/<folder> load: as a name or a module's
    attribute (imports, assignments and plain Python's reads are no kernel's reads)."""
    found = set()
    for path in sorted((PACKAGE / folder).glob("*.py")):
        kernels = [n for n in ast.walk(ast.parse(path.read_text(), str(path))) if _is_kernel(n)]
        for node in (n for kernel in kernels for n in ast.walk(kernel)):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                name = node.id
            elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load):
                name = node.attr
            else:
                continue
            if name.startswith(prefix):
                found.add(name)
    return found


def slot_constants(module, prefix: str) -> dict[str, int]:
    return {name: value for name, value in vars(module).items() if name.startswith(prefix) and isinstance(value, int)}


def attributes_read(path: str) -> set[str]:
    """Attribute names loaded in datmo_cli/<path> (`p.landmark_match` -> landmark_match)."""
    tree = ast.parse((PACKAGE / path).read_text())
    return {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Load)}


def keys_of(section) -> list[str]:
    return [f.name for f in fields(section)]


def check_table(keys: tuple[str, ...], slots: dict[str, int], prefix: str, read: set[str], extra: dict[str, int]):
    """What is wrong with one name table (empty: nothing): a key without its slot, a slot without its key, a slot
    no kernel reads."""
    wrong = []
    for i, key in enumerate(keys):
        name = prefix + key.upper()
        if slots.get(name) != i:
            wrong.append(f"key {key}: no slot {name} = {i} (found {slots.get(name)})")
    named = {prefix + key.upper() for key in keys} | set(extra)
    wrong += [f"slot {name} is no key of the table" for name in sorted(set(slots) - named)]
    wrong += [f"slot {name}: no kernel reads it" for name in sorted(set(slots) - read)]
    return wrong


def test_every_feature_slot_is_a_key_and_every_key_a_slot_the_kernels_read():
    slots = slot_constants(feature_layout, "FP_")
    read = slots_read("perception", "FP_")
    assert check_table(feature_layout.FEATURE_PARAM_NAMES, slots, "FP_", read, {}) == []
    assert len(slots) == feature_layout.N_FEATURE_PARAMS == len(FeatureParams().kernel_vector())


def test_every_track_slot_is_a_key_and_every_key_a_slot_the_kernels_read():
    slots = slot_constants(state, "P_")
    read = slots_read("tracking", "P_")
    assert check_table(state.PARAM_NAMES, slots, "P_", read, TRACK_EXTRA_SLOTS) == []
    assert {n: slots[n] for n in TRACK_EXTRA_SLOTS} == TRACK_EXTRA_SLOTS
    assert len(TrackingParams().kernel_vector()) == state.N_PARAMS + len(TRACK_EXTRA_SLOTS)


@pytest.mark.parametrize(
    ("section", "table", "elsewhere"),
    [
        (FeatureParams, feature_layout.FEATURE_PARAM_NAMES, FEATURES_ELSEWHERE),
        (TrackingParams, state.PARAM_NAMES, TRACK_ELSEWHERE),
    ],
    ids=["features", "track"],
)
def test_every_key_is_in_its_name_table_or_listed_where_it_is_read(section, table, elsewhere):
    keys = keys_of(section)
    assert len(set(table)) == len(table)
    assert not set(table) & set(elsewhere)
    assert set(keys) - set(table) - set(elsewhere) == set(), "keys in neither the name table nor the list"
    assert set(table) | set(elsewhere) <= set(keys), "listed names that are no key"
    for key, path in elsewhere.items():
        assert key in attributes_read(path), f"{key} is not read in {path}"


def test_tracking_names_the_keys_outside_its_vector_alike():
    bound = {f.name for f in fields(TrackingParams) if f.metadata["bound"] is not None}
    assert set(TrackingParams.not_in_kernels) == set(TRACK_ELSEWHERE) & bound


def _moved(value):
    return value + 1 if isinstance(value, int) else value * 1.25


@pytest.mark.parametrize("key", feature_layout.FEATURE_PARAM_NAMES)
def test_each_feature_key_moves_its_own_slot_alone(key):
    base = FeatureParams()
    value = _moved(getattr(base, key))
    moved = base.replace(**{key: value}).kernel_vector()
    slot = getattr(feature_layout, f"FP_{key.upper()}")
    conversion = dict(feature_layout.FEATURE_PARAMS)[key]
    want = math.radians(value) if conversion == "radians" else value
    assert moved[slot] == pytest.approx(want, rel=1e-12)
    others = [i for i in range(len(moved)) if i != slot]
    assert (moved[others] == base.kernel_vector()[others]).all()


def test_the_degree_keys_reach_the_kernels_in_radians():
    degrees = {f.name for f in fields(FeatureParams) if f.metadata["bound"] and f.metadata["bound"].unit == "degrees"}
    table = dict(feature_layout.FEATURE_PARAMS)
    assert {k for k, c in table.items() if c == "radians"} == degrees & set(table)
    assert set(table.values()) <= {"", "radians"}


@pytest.mark.parametrize("key", ["circle_check_extent", "circle_check_radius"])
def test_the_retired_circle_checks_are_refused_naming_the_rule_that_replaced_them(tmp_path, key):
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    cfg = tmp_path / "old.toml"
    cfg.write_text(f"[features]\n{key} = 0.3\n")
    result = CliRunner().invoke(cli, ["config", "--config", str(cfg)])
    assert result.exit_code != 0 and result.stderr.count("\n") == 1
    assert result.stderr.startswith(f"datmo: error: {cfg}: features.{key}: no longer a parameter: every single-line")
    shown = CliRunner().invoke(cli, ["config"])
    assert shown.exit_code == 0 and "circle_min_points" in shown.output and key not in shown.output
