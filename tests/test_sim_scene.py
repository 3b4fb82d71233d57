"""Scene files: the built-in scenes load and are physically sane; broken files give clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.base.errors import ConfigError, InputError
from datmo_cli.logs.vocabulary import CLASS_BENCH, CLASS_CIRCLE_OBJECT, CLASS_COLUMN, CLASS_PERSON, CLASS_WALL_CORNER
from datmo_cli.sim.scene import builtin_scenes, load_scene, parse_scene
from datmo_cli.sim.simulate import simulate_scene

pytestmark = pytest.mark.unit

MINIMAL = """
name = "mini"
[[wall]]
points = [[1.0, -2.0], [3.0, -2.0], [3.0, 2.0]]
[[person]]
name = "p"
path = [[1.0, 0.0], [2.0, 1.0]]
"""


def test_builtin_scenes_are_listed_and_load():
    names = builtin_scenes()
    assert {"hall", "corridor", "crowd", "static", "patrol"} <= set(names)
    for name in names:
        scene = load_scene(name)
        assert scene.name == name and names[name]


def test_hall_is_the_papers_experiment():
    s = load_scene("hall")
    assert len(s.columns) == 2 and len(s.benches) == 2 and len(s.people) == 2
    pulled = [p for p in s.platforms if p.pulled_by]
    assert len(pulled) == 1 and pulled[0].wire == pytest.approx(2.0)
    assert np.allclose(s.sensor.pose, 0) and s.sensor.path is None


@pytest.mark.parametrize("name", ["hall", "corridor", "crowd", "patrol"])
def test_movers_never_run_through_static_objects(name):
    r = simulate_scene(name, seed=3, rate=5.0, duration=60.0, noise_sigma=0.0)
    gt = r.truth.reshape(len(r.run), -1)
    cls = gt["classification"][0]
    for k in np.flatnonzero(np.isin(cls, [CLASS_PERSON, CLASS_CIRCLE_OBJECT])):
        reach = gt["length"][:, k].max() / 2
        for j in np.flatnonzero(np.isin(cls, [CLASS_COLUMN, CLASS_BENCH])):
            dx, dy = gt["world_x"][:, k] - gt["world_x"][0, j], gt["world_y"][:, k] - gt["world_y"][0, j]
            c, s = np.cos(gt["orientation"][0, j]), np.sin(gt["orientation"][0, j])
            along, across = np.abs(c * dx + s * dy), np.abs(-s * dx + c * dy)
            # outside the static object's bounding box grown by the mover's half-size
            clear = (along > gt["length"][0, j] / 2 + reach) | (across > gt["width"][0, j] / 2 + reach)
            assert clear.all(), (name, r.objects[k].name, r.objects[j].name)


def test_hall_people_are_mostly_visible_and_the_platform_briefly_occluded():
    r = simulate_scene("hall", seed=0)
    gt = r.truth.reshape(len(r.run), -1)
    in_view = gt["x"] > 0.3
    people = np.flatnonzero(gt["classification"][0] == CLASS_PERSON)
    platform = int(np.flatnonzero(gt["classification"][0] == CLASS_CIRCLE_OBJECT)[0])
    for k in people:
        assert gt["visible"][in_view[:, k], k].mean() > 0.85
    hidden = in_view[:, platform] & (gt["visible"][:, platform] == 0)
    assert 0 < hidden.sum() < 0.1 * in_view[:, platform].sum()
    corners = gt["classification"][0] == CLASS_WALL_CORNER
    assert corners.sum() >= 6 and gt["visible"][:, corners].any(axis=0).sum() >= 4


@pytest.mark.parametrize(
    "text,message",
    [
        ('name = "x\n', "line 1"),
        ("[[person]]\nname = 'a'\npath = [[0, 0], [1, 1]]\nsped = 2\n", "[[person]] 1: unknown key 'sped'"),
        ("[[person]]\npath = [[0, 0], [1, 1]]\nspeed = -1\n", "[[person]] 1, key 'speed': must be > 0"),
        ("[[column]]\ncenter = [1, 2]\n", "[[column]] 1: missing key 'radius'"),
        ("[[column]]\ncenter = [1, 'a']\nradius = 1\n", "key 'center': must be a list of 2 numbers"),
        ("[[wall]]\npoints = [[0, 0]]\n", "[[wall]] 1, key 'points'"),
        ("[[wall]]\npoints = [[0, 0], [0, 0], [1, 1]]\n", "consecutive points are equal"),
        ("[[platform]]\npulled_by = 'ghost'\n", "no person is named 'ghost'"),
        ("[[person]]\nposition = [1, 1]\npath = [[0, 0], [1, 1]]\n", "either 'path'"),
        ("[[person]]\npath = [[0, 0], [1, 1]]\npauses = [[5, 1.0]]\n", "key 'pauses'"),
        ("duration = 'long'\n", "top level, key 'duration'"),
        ("wall = 3\n", "'wall' must be an array of tables"),
        ("[crowd]\narea = [[5, 5], [1, 1]]\n", "[crowd], key 'area'"),
        ("bogus = 1\n", "unknown key 'bogus'"),
        ("[sensor]\npose = [0, 0, 0]\npath = [[0, 0], [1, 0]]\n", "not both"),
    ],
)
def test_broken_scene_files_name_the_key_or_line(text, message):
    with pytest.raises(ConfigError) as err:
        parse_scene(text, "my.toml")
    assert str(err.value).startswith("my.toml: ") and message in str(err.value)


def test_scene_files_by_path(tmp_path):
    path = tmp_path / "mini.toml"
    path.write_text(MINIMAL)
    s = load_scene(str(path))
    assert s.name == "mini" and len(s.walls) == 1 and s.people[0].name == "p"
    with pytest.raises(InputError, match="not found"):
        load_scene(str(tmp_path / "missing.toml"))
    with pytest.raises(ConfigError, match="unknown scene 'atlantis'"):
        load_scene("atlantis")


def test_crowd_walkers_mostly_keep_apart():
    r = simulate_scene("crowd", seed=1, people=6, noise_sigma=0.0)
    gt = r.truth.reshape(len(r.run), -1)
    p = np.flatnonzero(gt["classification"][0] == CLASS_PERSON)
    assert len(p) == 6
    x, y = gt["world_x"][:, p], gt["world_y"][:, p]
    d = np.hypot(x[:, :, None] - x[:, None, :], y[:, :, None] - y[:, None, :]) + 99 * np.eye(6)
    assert (d.min(axis=(1, 2)) < 0.6).mean() < 0.05
    assert gt["moving"][:, p].mean() > 0.6 and gt["visible"][:, p].mean() > 0.9
