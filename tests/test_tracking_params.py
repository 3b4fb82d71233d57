"""Tracking parameters: defaults, TOML loading and clear errors; the parameters that share a name with a
features parameter."""

from __future__ import annotations

import pytest

from datmo_cli.bounds import validate
from datmo_cli.config import load
from datmo_cli.errors import ConfigError
from datmo_cli.perception.params import FeatureParams
from datmo_cli.tracking.params import TrackingParams


def test_defaults_follow_the_paper():
    p = TrackingParams()
    assert p.d_max == 1.5
    assert p.confirm_hits >= 2


def test_toml_track_table(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[track]\nprocess_noise = 3.5\nconfirm_hits = 4\nconfirm_window = 6\n")
    p = load(f).track
    assert (p.process_noise, p.confirm_hits, p.confirm_window) == (3.5, 4, 6)


@pytest.mark.parametrize("values, message", [
    ({"nope": 1}, "track.nope: unknown parameter"),
    ({"gate": "x"}, "track.gate: expected float"),
    ({"confirm_hits": 2.5}, "track.confirm_hits: expected int"),
    ({"confirm_hits": 1}, "no track confirmed from one scan"),
    ({"confirm_hits": 4, "confirm_window": 3}, "confirm_window: must be at least"),
    ({"d_max": 0}, "track.d_max: must be positive"),
])
def test_bad_values_name_the_key(values, message):
    with pytest.raises(ConfigError, match=message):
        validate(TrackingParams, values)


def test_bad_toml_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[track\n")
    with pytest.raises(ConfigError, match="bad.toml"):
        load(f)
    with pytest.raises(ConfigError, match="no such file"):
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
