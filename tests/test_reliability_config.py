"""A config file says what it means or is refused: a misspelt table (`[tracks]`,
`[Features]`) was ignored, so its values silently did not apply; a minimum above its maximum (`step_min >
step_max`) was accepted, so nothing could lie between them. Both are one line naming the file and the key."""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from fuzzing import tally

from datmo_cli.base.bounds import bounds_of, min_max_pairs
from datmo_cli.base.errors import ConfigError
from datmo_cli.cli import cli
from datmo_cli.passes.config import SECTIONS, load

pytestmark = pytest.mark.cli


@pytest.mark.parametrize(
    "table, hint",
    [
        ("tracks", "track"),
        ("Features", "features"),
        ("TRACK", "track"),
        ("feature", "features"),
        ("Track", "track"),
        ("segments", None),
        ("datmo", None),
    ],
)
def test_a_misspelt_or_unknown_table_is_refused_naming_it(tmp_path, table, hint):
    config = tmp_path / "c.toml"
    config.write_text(f"[{table}]\ngate = 3.0\n")
    try:
        with pytest.raises(ConfigError) as exc:
            load(config)
        message = str(exc.value)
        assert message.startswith(f"{config}: [{table}]: unknown table"), message
        assert (f"did you mean [{hint}]?" in message) if hint else "did you mean" not in message
        result = CliRunner().invoke(cli, ["config", "--config", str(config)])
        assert result.exit_code == 1 and result.stderr == f"datmo: error: {message}\n"
    except BaseException:
        tally("config: misspelt tables refused", failed=True)
        raise
    tally("config: misspelt tables refused")


def test_the_two_tables_and_top_level_keys_still_read(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("gate = 12.0\n[features]\nc0 = 0.1\n")
    cfg = load(config)
    assert (cfg.features.c0, cfg.track.gate) == (0.1, 12.0)


def test_every_min_max_pair_is_found():
    assert min_max_pairs(SECTIONS["features"]) == [
        ("circle_radius_min", "circle_radius_max"),
        ("bench_min_length", "bench_max_length"),
    ]
    assert min_max_pairs(SECTIONS["track"]) == [("step_min", "step_max")]


PAIRS = [(s, lo, hi) for s, cls in SECTIONS.items() for lo, hi in min_max_pairs(cls)]


@pytest.mark.parametrize("section, lo, hi", PAIRS)
def test_a_minimum_above_its_maximum_is_refused(tmp_path, section, lo, hi):
    b = bounds_of(SECTIONS[section])
    top = min(b[lo].hi, b[hi].hi)
    small, big = top / 4, top / 2  # each within both ranges
    config = tmp_path / "c.toml"
    config.write_text(f"[{section}]\n{lo} = {big}\n{hi} = {small}\n")
    try:
        with pytest.raises(ConfigError, match=rf"c.toml: {section}(\.{lo})?: {lo} .*{hi}|c.toml: {section}\.{lo}: "):
            load(config)
        with pytest.raises(ConfigError, match=lo):  # the options too
            load(None, {section: {lo: big, hi: small}})
        config.write_text(f"[{section}]\n{lo} = {small}\n{hi} = {big}\n")
        assert load(config).get(f"{section}.{lo}") == small
    except BaseException:
        tally("config: min/max pairs", failed=True)
        raise
    tally("config: min/max pairs")


def test_step_min_above_step_max_is_one_line(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("[track]\nstep_min = 2.0\nstep_max = 1.0\n")
    result = CliRunner().invoke(cli, ["config", "--config", str(config)])
    assert result.exit_code == 1
    assert result.stderr == (
        f"datmo: error: {config}: track.step_min: 2 m is above step_max = 1 m; a minimum must be at most its maximum\n"
    )
    config.write_text("[track]\nstep_min = 1.0\nstep_max = 1.0\n")  # equal: allowed
    assert load(config).track.step_min == 1.0
