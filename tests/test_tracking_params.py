"""Tracking parameters: defaults, TOML loading and clear errors; the parameters that share a name with a
features parameter."""

from __future__ import annotations

import pytest

from datmo_cli.base.bounds import validate
from datmo_cli.base.errors import ConfigError, InputError
from datmo_cli.passes.config import DatmoConfig, load
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking.params import TrackingParams

pytestmark = pytest.mark.unit


def test_defaults_follow_the_paper():
    p = TrackingParams()
    assert p.d_max == 1.5
    assert p.confirm_hits >= 2


def test_toml_track_table(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[track]\nprocess_noise = 3.5\nconfirm_hits = 4\nconfirm_window = 6\n")
    p = load(f).track
    assert (p.process_noise, p.confirm_hits, p.confirm_window) == (3.5, 4, 6)


@pytest.mark.parametrize(
    "values, message",
    [
        ({"nope": 1}, "track.nope: unknown parameter"),
        ({"gate": "x"}, "track.gate: expected float"),
        ({"confirm_hits": 2.5}, "track.confirm_hits: expected int"),
        ({"confirm_hits": 1}, "no track confirmed from one scan"),
        ({"confirm_hits": 4, "confirm_window": 3}, "confirm_window: must be at least"),
        ({"d_max": 0}, "track.d_max: must be positive"),
    ],
)
def test_bad_values_name_the_key(values, message):
    with pytest.raises(ConfigError, match=message):
        validate(TrackingParams, values)


def test_bad_toml_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[track\n")
    with pytest.raises(ConfigError, match="bad.toml"):
        load(f)
    with pytest.raises(InputError, match="missing.toml: no such file"):  # every user-named file: input_files
        load(tmp_path / "missing.toml")


def test_the_features_leg_radius_max_of_an_old_config_is_refused_naming_its_new_key(tmp_path):
    """features' leg_radius_max (circles larger are column candidates, 0.13) was not track's (circles up to it
    may be legs, 0.2): it is column_radius_min now, and an old file using it is told so, not misread."""
    f = tmp_path / "old.toml"
    f.write_text("[features]\nleg_radius_max = 0.15\n")
    with pytest.raises(ConfigError, match=r"old.toml: features.leg_radius_max: renamed to column_radius_min"):
        load(f)
    f.write_text("[features]\ncolumn_radius_min = 0.15\n[track]\nleg_radius_max = 0.25\n")
    cfg = load(f)
    assert (cfg.features.column_radius_min, cfg.track.leg_radius_max) == (0.15, 0.25)
    assert (FeatureParams().column_radius_min, TrackingParams().leg_radius_max) == (0.13, 0.2)


def test_d_max_is_one_parameter_at_home_in_features_and_read_from_track_for_old_files(tmp_path):
    """The paper's d_max: lines and objects larger are static, for landmarks and tracking alike."""
    assert FeatureParams().d_max == TrackingParams().d_max == 1.5
    f = tmp_path / "c.toml"
    for text in (
        "[features]\nd_max = 2.5\n",
        "[track]\nd_max = 2.5\n",
        "[features]\nd_max = 2.5\n[track]\nd_max = 2.5\n",
    ):
        f.write_text(text)
        cfg = load(f)
        assert (cfg.features.d_max, cfg.track.d_max) == (2.5, 2.5), text
        assert "d_max" in cfg.to_dict()["features"] and "d_max" not in cfg.to_dict()["track"]
    f.write_text("[features]\nd_max = 2.0\n[track]\nd_max = 2.5\n")
    with pytest.raises(ConfigError, match=r"c.toml: track.d_max and features.d_max are one parameter"):
        load(f)
    assert load(None, {"track": {"d_max": 3.0}}).features.d_max == 3.0
    assert DatmoConfig(FeatureParams().replace(d_max=2.0)).track.d_max == 2.0


def test_keys_outside_any_table_go_to_the_section_that_declares_them(tmp_path):
    f = tmp_path / "flat.toml"
    f.write_text("c0 = 0.1\ngate = 9.0\nd_max = 2.0\n")
    cfg = load(f)
    assert (cfg.features.c0, cfg.track.gate, cfg.features.d_max, cfg.track.d_max) == (0.1, 9.0, 2.0, 2.0)
    f.write_text("nope = 1\n")
    with pytest.raises(ConfigError, match="flat.toml: nope: unknown parameter"):
        load(f)


def test_every_numeric_track_parameter_reaches_the_kernels_in_its_slot():
    from datmo_cli.passes.config import BOUNDS
    from datmo_cli.tracking import state

    kernel = set(BOUNDS["track"]) - set(TrackingParams.not_in_kernels)
    assert set(state.PARAM_NAMES) == kernel and len(state.PARAM_NAMES) == state.N_PARAMS
    p = TrackingParams().replace(gate=9.5, tail_length=0)
    v = p.kernel_vector()
    assert v.dtype == "float64" and v[state.P_GATE] == 9.5 and v[state.P_TAIL_LENGTH] == 1
    assert load(None, {"features": {"d_max": 2.0}}).track.kernel_vector()[state.P_D_MAX] == 2.0


def test_the_kernels_parameter_slots_are_the_track_fields_by_name():
    """state.P_<NAME> is the slot of field <name> in kernel_vector, for every numeric [track] field."""
    from dataclasses import fields

    from datmo_cli.tracking import state

    numeric = [
        f.name
        for f in fields(TrackingParams)
        if f.metadata.get("bound") is not None and f.name not in TrackingParams.not_in_kernels
    ]
    assert sorted(state.PARAM_NAMES) == sorted(numeric)
    assert len(state.PARAM_NAMES) == state.N_PARAMS
    defaults = TrackingParams()
    vec = defaults.kernel_vector()
    for i, name in enumerate(state.PARAM_NAMES):
        assert getattr(state, f"P_{name.upper()}") == i, name
        if name != "tail_length":
            assert vec[i] == getattr(defaults, name), name
