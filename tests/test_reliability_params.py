"""Every numeric parameter is checked in one place (datmo_cli/base/bounds.py, against the Bound its field
declares): NaN, infinities and values outside its range give one line naming the option or TOML key and the
range, a non-zero exit, no traceback and no output; the defaults and the bounds themselves pass.

The parameters are enumerated from the configuration's fields, bounds.OPTIONS and the commands themselves, so
a new one is covered without touching this file."""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import asdict, fields

import click
import pytest
from click.testing import CliRunner
from conftest import SAMPLE_LOGS
from fuzzing import tally
from hypothesis import given
from hypothesis import strategies as st

from datmo_cli.base import bounds
from datmo_cli.base.bounds import OPTIONS, Bound, OptionError, check, validate
from datmo_cli.base.errors import ConfigError
from datmo_cli.cli import COMMANDS, cli
from datmo_cli.commands.types import Bounded, option_name
from datmo_cli.passes.config import BOUNDS, SECTIONS, load
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking.params import TrackingParams

pytestmark = pytest.mark.cli

TABLES = {s: (BOUNDS[s], SECTIONS[s]) for s in SECTIONS}
KEYS = [(table, key) for table, (b, _) in TABLES.items() for key in sorted(b)]

# a key at a bound contradicts another key's default: the other key set so that the pair is consistent
COMPANIONS = {
    ("features", "circle_radius_min", "hi"): {"circle_radius_max": 5.0},
    ("features", "circle_radius_max", "lo"): {"circle_radius_min": 0.001},
    ("features", "bench_min_length", "hi"): {"bench_max_length": 20.0},
    ("features", "bench_max_length", "lo"): {"bench_min_length": 0.01},
    ("track", "step_min", "hi"): {"step_max": 5.0},
    ("track", "step_max", "lo"): {"step_min": 0.0},
    ("track", "confirm_window", "lo"): {"confirm_hits": 2},
    ("track", "confirm_hits", "hi"): {"confirm_window": 16},
}


def numeric_fields(cls: type) -> set[str]:
    return {f.name for f in fields(cls) if f.type in ("float", "int", float, int)}


def outside(b: Bound) -> list[float | int]:
    """Values just outside each end of `b`: the open end itself, or the next number beyond a closed one."""
    if b.integer:
        return [int(b.lo) - 1, int(b.hi) + 1]
    return [b.lo if b.lo_open else math.nextafter(b.lo, -math.inf), math.nextafter(b.hi, math.inf)]


def inside(b: Bound) -> dict[str, float | int]:
    """The bounds themselves where closed (just inside an open lower end)."""
    lo = b.lo + (b.hi - b.lo) * 1e-3 if b.lo_open else b.lo
    return {"lo": int(lo) if b.integer else lo, "hi": b.hi}


def bad_values(b: Bound) -> list:
    return [math.nan, math.inf, -math.inf, *outside(b)]


# ------------------------------------------------------------------------------------ the one place


def test_every_numeric_parameter_has_a_bound_and_its_default_passes():
    for table, (table_bounds, cls) in TABLES.items():
        assert set(table_bounds) == numeric_fields(cls), table
        defaults = asdict(cls())
        for key, b in table_bounds.items():
            assert b.lo < b.hi and b.describe()
            assert b.integer == isinstance(defaults[key], int), key
            assert check(b, defaults[key], key) == defaults[key], key
    for b in OPTIONS.values():
        assert b.lo < b.hi and math.isfinite(b.lo) and math.isfinite(b.hi)


@pytest.mark.parametrize("table, key", KEYS)
def test_bad_values_of_every_key_are_refused_naming_it_and_the_range(table, key):
    table_bounds, cls = TABLES[table]
    b = table_bounds[key]
    for value in bad_values(b):
        tally("params: bad TOML values refused")
        with pytest.raises(ConfigError) as exc:
            validate(cls, {key: value})
        message = str(exc.value)
        assert message.startswith(f"{table}.{key}: ") and "\n" not in message, message
        if not (b.integer and isinstance(value, float)):  # a float for an int key is a type error
            assert b.describe() in message, message
    for value in ("1", True, [1]):
        with pytest.raises(ConfigError, match=f"{table}.{key}: expected"):
            validate(cls, {key: value})


@pytest.mark.parametrize("table, key", KEYS)
def test_the_bounds_themselves_and_the_defaults_pass(table, key):
    table_bounds, cls = TABLES[table]
    assert validate(cls, asdict(cls())) == cls()
    for end, value in inside(table_bounds[key]).items():
        values = {key: value, **COMPANIONS.get((table, key, end), {})}
        assert getattr(validate(cls, values), key) == value


@pytest.mark.parametrize("literal", ["nan", "inf", "-inf", "1e400"])
def test_toml_values_name_the_file_and_the_key(tmp_path, literal):
    for table, key in KEYS:
        b = TABLES[table][0][key]
        config = tmp_path / "c.toml"
        config.write_text(f"[{table}]\n{key} = {literal}\n")
        with pytest.raises(ConfigError) as exc:
            load(config)
        tally("params: bad TOML values refused")
        assert str(exc.value).startswith(f"{config}: {table}.{key}: "), str(exc.value)
        assert b.integer or b.describe() in str(exc.value)


@pytest.mark.parametrize("table, other", [("features", "track"), ("track", "features")])
def test_a_stage_name_that_is_not_a_table_is_said_so(tmp_path, table, other):
    config = tmp_path / "c.toml"
    config.write_text(f"{table} = 3\n")
    with pytest.raises(ConfigError, match=rf"c.toml: {table} must be a table \(\[{table}\]"):
        load(config)
    config.write_text(f"{other} = [1]\n[{table}]\n")
    with pytest.raises(ConfigError, match=f"{other} must be a table"):
        load(config)


@pytest.mark.parametrize(
    "values, names",
    [
        (
            {"theta_resolution": 0.1, "rho_resolution": 0.001},
            ("theta_resolution", "rho_resolution", "line accumulator"),
        ),
        ({"circle_radius_step": 0.001, "circle_cell": 0.001}, ("circle_radius_step", "circle_cell", "circle votes")),
        ({"circle_radius_max": 5, "circle_window": 0.5}, ("circle_radius_step", "circle_cell", "circle votes")),
    ],
)
def test_feature_parameters_that_combine_into_too_big_a_kernel_are_refused_naming_both(values, names):
    with pytest.raises(ConfigError) as exc:
        validate(FeatureParams, values)
    assert all(n in str(exc.value) for n in names), str(exc.value)


def test_a_background_grid_too_big_is_refused_naming_both_and_off_it_allocates_nothing():
    with pytest.raises(
        ConfigError,
        match="background_extent 100 m and background_cell 0.05 m make a background grid 4,000 cells a side",
    ):
        validate(TrackingParams, {"background_extent": 100, "background_cell": 0.05})
    assert validate(TrackingParams, {"background_extent": 100, "background_cell": 0.05, "background_time": 0})


def test_the_background_limit_is_what_the_tracker_allocates():
    import numpy as np

    from datmo_cli.logs.scan import ScanGeometry
    from datmo_cli.tracking.tracker import Tracker

    t = validate(TrackingParams, {"background_extent": 100.0, "background_cell": 0.1})
    geometry = ScanGeometry(
        angle_min=-np.pi / 2,
        angle_increment=np.radians(0.5),
        n_beams=361,
        range_min=0.0,
        range_max=80.0,
        scan_time=0.2,
        frame_id="laser",
    )
    grid = Tracker(t, geometry)._bg[0]
    assert len(grid) == bounds.background_side(100.0, 0.1) ** 2 <= bounds.BACKGROUND_SIDE**2


@pytest.mark.parametrize(
    "values",
    [
        {"rho_resolution": 0.001},  # the largest line accumulator accepted
        {"theta_resolution": 0.1, "rho_resolution": 0.011},
        {"circle_radius_step": 0.001, "circle_cell": 0.003, "circle_window": 0.03},  # the most circle votes
    ],
)
def test_features_run_at_the_largest_settings_accepted(values):
    """The kernels allocate and finish at the corners of the accepted ranges (no MemoryError, no hang)."""
    from datmo_cli.logs import mcapio
    from datmo_cli.perception.features import extract_run

    p = validate(FeatureParams, {**values, "leg_model": "paper"})
    cells = bounds.line_accumulator_cells(p.theta_resolution, p.rho_resolution)
    votes = bounds.circle_votes(
        p.circle_radius_min, p.circle_radius_max, p.circle_radius_step, p.circle_window, p.circle_cell
    )
    assert cells <= bounds.LINE_ACCUMULATOR_CELLS and votes <= bounds.CIRCLE_VOTES
    assert max(cells / bounds.LINE_ACCUMULATOR_CELLS, votes / bounds.CIRCLE_VOTES) > 0.5
    run = mcapio.read_run(HALL)
    small = type(run)(run.stamps[:3], run.ranges[:3], run.geometry)
    f = extract_run(small, p, landmarks=False, threads=1)
    assert len(f.line_offsets) == len(f.circle_offsets) == 4


@given(
    key=st.sampled_from(KEYS),
    value=st.one_of(
        st.floats(), st.integers(min_value=-(2**80), max_value=2**80), st.booleans(), st.text(max_size=4), st.none()
    ),
)
def test_fuzz_any_value_is_either_in_range_or_one_clean_error(key, value):
    table, name = key
    table_bounds, cls = TABLES[table]
    b = table_bounds[name]
    try:
        p = validate(cls, {name: value})
    except ConfigError as exc:
        tally("params: random values through the validator")
        assert "\n" not in str(exc) and name in str(exc)
        return
    ok = (
        not isinstance(value, bool)
        and isinstance(value, int | float)
        and b.lo <= value <= b.hi
        and not (b.lo_open and value == b.lo)
        and (isinstance(value, int) or not b.integer)
    )
    tally("params: random values through the validator", failed=not ok)
    assert ok, (key, value)
    assert getattr(p, name) == value
    f = p if table == "features" else FeatureParams()
    assert bounds.line_accumulator_cells(f.theta_resolution, f.rho_resolution) <= bounds.LINE_ACCUMULATOR_CELLS
    assert (
        bounds.circle_votes(
            f.circle_radius_min, f.circle_radius_max, f.circle_radius_step, f.circle_window, f.circle_cell
        )
        <= bounds.CIRCLE_VOTES
    )


# ------------------------------------------------------------------------------------ command-line options


def commands() -> list[tuple[str, click.Command]]:
    group = cli
    ctx = click.Context(group)
    return [(name, group.get_command(ctx, name)) for name in group.list_commands(ctx)]


def _numeric(t: click.ParamType) -> bool:
    if isinstance(t, click.Tuple):
        return any(_numeric(x) for x in t.types)
    return isinstance(t, Bounded | click.types.IntParamType | click.types.FloatParamType)


def bounded_options() -> list[tuple[str, click.Option, Bounded]]:
    out = []
    for name, command in commands():
        for param in command.params:
            types = param.type.types if isinstance(param.type, click.Tuple) else [param.type]
            out += [(name, param, t) for t in types if isinstance(t, Bounded)]
    return out


ALL_BOUNDS = [*BOUNDS["features"].values(), *BOUNDS["track"].values(), *OPTIONS.values()]
OPTION_CASES = [(name, param.opts[-1], t) for name, param, t in bounded_options()]


def test_every_numeric_option_is_bounded_by_a_bound_of_the_one_place():
    assert len(commands()) == len(COMMANDS)
    for name, command in commands():
        for param in command.params:
            if not _numeric(param.type):
                continue
            types = param.type.types if isinstance(param.type, click.Tuple) else [param.type]
            assert all(isinstance(t, Bounded) for t in types), f"datmo {name} {param.opts}: not a Bounded type"
            assert all(any(t.bound is b for b in ALL_BOUNDS) for t in types), (name, param.opts)
    assert len(OPTION_CASES) >= 25


def test_every_numeric_option_shows_its_range_in_its_help():
    for name, command in commands():
        ctx = click.Context(command, info_name=name)
        for param in command.params:
            if isinstance(param, click.Option) and _numeric(param.type):
                types = param.type.types if isinstance(param.type, click.Tuple) else [param.type]
                text = param.get_help_record(ctx)[1]
                assert all(t.bound.describe() in text for t in types), (name, param.opts, text)
    result = CliRunner().invoke(cli, ["track", "--help"], terminal_width=200)
    assert result.exit_code == 0 and "Range: 0 < x ≤ 1000." in " ".join(result.output.split())


@pytest.mark.parametrize("command, option, ptype", OPTION_CASES, ids=[f"{c} {o}" for c, o, _ in OPTION_CASES])
def test_every_numeric_option_refuses_bad_values_naming_it_and_the_range(command, option, ptype):
    param = next(p for _, p, t in bounded_options() if t is ptype)
    name = option_name(param)
    b = ptype.bound
    for value in [*bad_values(b), "x", ""]:
        tally("params: bad option values refused")
        with pytest.raises(OptionError) as exc:
            ptype.convert(str(value), param, None)
        message = str(exc.value)
        assert message.startswith(f"{name}: ") and b.describe() in message and "\n" not in message, message
        assert exc.value.exit_code == 2
    for value in inside(b).values():
        assert ptype.convert(str(value), param, None) == value
    if param.default is not None and not isinstance(param.type, click.Tuple):
        assert ptype.convert(param.default, param, None) == param.default


@given(text=st.one_of(st.text(max_size=12), st.floats().map(repr), st.integers(-(2**70), 2**70).map(str)))
def test_fuzz_any_option_text_is_a_number_in_range_or_one_clean_error(text):
    for _, param, t in bounded_options()[:40]:
        tally("params: random option texts")
        try:
            value = t.convert(text, param, None)
        except OptionError as exc:
            assert "\n" not in str(exc) and option_name(param) in str(exc)
            continue
        assert t.bound.lo <= value <= t.bound.hi and math.isfinite(value)


# ------------------------------------------------------------------------------------ whole commands


HALL = SAMPLE_LOGS / "hall.mcap"


def refused(tmp_path, args: list[str], *names: str) -> str:
    """Run datmo ARGS (outputs into tmp_path): one error line naming `names`, non-zero exit, no traceback,
    nothing written, the input untouched."""
    before = sorted(os.listdir(tmp_path))
    digest = hashlib.sha256(HALL.read_bytes()).hexdigest()
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code not in (0, None), result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: "), result.stderr
    assert all(n in lines[0] for n in names), (names, lines[0])
    assert "Traceback" not in result.output
    assert sorted(os.listdir(tmp_path)) == before
    assert hashlib.sha256(HALL.read_bytes()).hexdigest() == digest
    return lines[0]


@pytest.mark.parametrize(
    "args, names",
    [
        (["track", HALL, "--measurement-noise", "nan"], ["--measurement-noise", "0 < x ≤ 10 m"]),
        (["track", HALL, "--process-noise", "1e308"], ["--process-noise", "at most 1000"]),
        (["track", HALL, "--process-noise", "inf"], ["--process-noise", "not a finite number"]),
        (["track", HALL, "--gate", "nan"], ["--gate"]),
        (["track", HALL, "--d-max", "nan"], ["--d-max"]),
        (["track", HALL, "--delete-after", "nan"], ["--delete-after"]),
        (["track", HALL, "--confirm", "3", "nan"], ["--confirm", "expected a whole number"]),
        (["features", HALL, "--rho-resolution", "1e-9"], ["--rho-resolution", "0.001 ≤ x ≤ 1 m"]),
        (["features", HALL, "--circle-radius", "0.05", "inf"], ["--circle-radius"]),
        (["segment", HALL, "--c0", "-inf"], ["--c0"]),
        (["run", HALL, "--threads", "0"], ["--threads"]),
        (["evaluate", HALL, "--min-mota", "nan"], ["--min-mota", "-100 ≤ x ≤ 1"]),
        (["evaluate", HALL, "--match-radius", "nan"], ["--match-radius"]),
        (["import", HALL, "--max-scans", "0"], ["--max-scans"]),
    ],
)
def test_bad_options_on_the_command_line(tmp_path, args, names):
    out = (
        ["-o", tmp_path / "out"]
        if args[0] in ("run",)
        else []
        if args[0] == "evaluate"
        else ["-o", tmp_path / "out.mcap"]
    )
    refused(tmp_path, [*args, *out], *names)


def test_simulate_a_billion_seconds_is_refused(tmp_path):
    refused(tmp_path, ["simulate", "--duration", "1e9", "-o", tmp_path / "x.mcap"], "--duration", "0 < x ≤ 3600 s")
    scene = tmp_path / "long.toml"
    scene.write_text("duration = 1e9\n")
    line = refused(tmp_path, ["simulate", "--scene", scene, "-o", tmp_path / "x.mcap"], "long.toml", "duration")
    assert "0 < x ≤ 3600 s" in line


@pytest.mark.parametrize(
    "command, toml, names",
    [
        ("track", "[track]\nprocess_noise = nan\n", ["track.process_noise", "not a finite number"]),
        ("features", "[features]\ncircle_radius_step = 1e-7\n", ["features.circle_radius_step"]),
        ("features", "[features]\ncircle_cell = 1e-6\n", ["features.circle_cell"]),
        ("track", "[track]\nbackground_cell = 1e-6\n", ["track.background_cell"]),
        ("track", "[track]\nbackground_extent = 1e12\n", ["track.background_extent"]),
        ("run", "[track]\nbackground_extent = 100\nbackground_cell = 0.05\n", ["background_extent", "background_cell"]),
        ("track", "features = 3\n", ["features must be a table"]),
    ],
)
def test_bad_config_files_on_the_command_line(tmp_path, command, toml, names):
    config = tmp_path / "c.toml"
    config.write_text(toml)
    out = tmp_path / ("out" if command == "run" else "out.mcap")
    refused(tmp_path, [command, HALL, "-o", out, "--config", config], "c.toml", *names)
