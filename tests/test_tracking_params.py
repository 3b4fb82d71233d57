"""Tracking parameters: defaults, TOML loading and clear errors."""

from __future__ import annotations

import pytest

from datmo_cli.errors import ConfigError
from datmo_cli.tracking.params import TrackingParams, from_dict, load_toml


def test_defaults_follow_the_paper():
    p = TrackingParams()
    assert p.d_max == 1.5
    assert p.confirm_hits >= 2


def test_toml_track_table(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[track]\nprocess_noise = 3.5\nconfirm_hits = 4\nconfirm_window = 6\n")
    p = load_toml(f)
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
        from_dict(values)


def test_bad_toml_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[track\n")
    with pytest.raises(ConfigError, match="bad.toml"):
        load_toml(f)
    with pytest.raises(ConfigError, match="no such file"):
        load_toml(tmp_path / "missing.toml")
