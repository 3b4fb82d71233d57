"""`datmo node`'s parameters (node_params): datmo's configuration keys as ROS 2 parameters, checked as a config
file's, and a live change taken by the running tracker (in process; the graph test, test_node_graph.py, sets one
through the parameter services)."""

import pytest

from datmo_cli.logs import mcapio
from tests.test_node import HALL

pytestmark = pytest.mark.unit

MOBILITY_DYNAMIC = 1  # datmo_msgs/Track


@pytest.mark.slow
def test_a_live_parameter_changes_the_running_tracker():
    """The stages' tracker takes a changed moving_speed at once; with the default some tracks stay dynamic
    over the same scans (so the graph test's 'none dynamic' is the change's doing)."""
    from datmo_cli import live
    from datmo_cli.logs import cdr, types
    from datmo_cli.passes.config import DatmoConfig
    from datmo_cli.ros2.node import retune_stages

    run = mcapio.read_run(HALL).slice(0, 160)

    def dynamic_after(config: DatmoConfig) -> int:
        stages = live.Stages(None, run.geometry, DatmoConfig(), has_tf=False)
        count = 0
        for i in range(0, 160, 20):
            if i == 80:
                retune_stages(stages, config)
            for m in stages.messages(run.slice(i, i + 20)):
                if m.topic == mcapio.TOPIC_TRACKS and i >= 120:
                    count += sum(
                        t["mobility"] == MOBILITY_DYNAMIC for t in cdr.decode(types.TRACKS, m.payload)["tracks"]
                    )
        return count

    assert dynamic_after(DatmoConfig()) > 0
    assert dynamic_after(DatmoConfig().replace(track={"moving_speed": 50.0})) == 0


def test_parameters_are_the_config_keys_with_the_config_files_checks():
    from datmo_cli.passes.config import DatmoConfig
    from datmo_cli.ros2.node_params import LIVE, Parameters

    p = Parameters(DatmoConfig().replace(track={"gate": 9.0}))
    assert p.get("track.gate") == 9.0 and p.get("track.d_max") is None and p.get("features.d_max") == 1.5
    assert "track.gate" in LIVE and "track.tail_length" not in LIVE and not any(n.startswith("features.") for n in LIVE)
    assert p.list(["track"], 1)[0] == [n for n in p.names() if n.startswith("track.")]
    assert p.set("track.gate", 12) == "" and p.config.track.gate == 12.0  # an integer for a float parameter
    assert p.set("track.confirm_hits", 3.5) == "track.confirm_hits: expected int, got 3.5"
    assert p.set("track.step_min", 5.0).startswith("track.step_min: 5 m is above step_max = 1 m")
    assert (
        p.set("track.d_max", 1.0) == "track.d_max: the same parameter as features.d_max, its home: set features.d_max"
    )
    assert p.set("track.leg_probability", 0.5).startswith("track.leg_probability: no longer a parameter")
    assert p.set("tracks.gate", 1.0).startswith("tracks.gate: unknown parameter")
    assert p.set("features.d_max", 2.0).startswith("features.d_max: read when the node starts")
    assert p.set("track.gate", None) == "track.gate: a parameter of datmo cannot be undeclared"
    assert p.config.track.gate == 12.0 and p.config.track.step_min == 0.1  # refusals leave it as it was
    d = p.describe("track.confirm_hits")
    assert (d.type, d.read_only, d.constraints) == (
        2,
        False,
        "2 ≤ n ≤ 16 scans (no track confirmed from one scan; 16 bits of history)",
    )
