"""Simulator speed: the hall scene at 361 beams (target >= 2,000 scans/s), end to end and by part."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import Row, best_of, print_lines, print_table
from datmo_cli.logs import mcapio, types
from datmo_cli.sim.raycast import cast
from datmo_cli.sim.scene import load_scene
from datmo_cli.sim.simulate import simulate_scene
from datmo_cli.sim.world import World

DURATION = 400.0  # s at 5 Hz: 2,000 scans


def main() -> None:
    scene = load_scene("hall")
    simulate_scene(scene, duration=2.0)  # warm-up: numba compilation or cache load
    n = int(DURATION * 5)
    t_sim = best_of(lambda: simulate_scene(scene, duration=DURATION))
    result = simulate_scene(scene, duration=DURATION)
    t_gt = best_of(result.ground_truth_payloads)

    def write() -> None:
        with tempfile.TemporaryDirectory() as tmp, mcapio.LogWriter(Path(tmp) / "sim.mcap") as w:
            w.write_scans(result.run)
            w.write_many(
                mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH, result.run.stamps, result.ground_truth_payloads()
            )

    t_write = best_of(write)

    world = World(scene, DURATION, np.random.SeedSequence(0))
    t = np.arange(n) / 5.0
    poses = world.sensor.poses(t)
    states = [(k, m.state(t)) for k, m in world.movers]
    circles = np.concatenate([s.circles for _, s in states], 1)
    owners = np.concatenate([np.full(s.circles.shape[1], k) for k, s in states])
    angles = result.sensor.angles()
    t_cast = best_of(lambda: cast(poses, angles, world.static, moving_circles=circles, moving_circle_owner=owners))
    rows = [
        Row(
            "simulate_scene hall (scans + ground truth)",
            n,
            t_sim,
            f"{result.sensor.n_beams} beams, {len(result.objects)} objects",
        ),
        Row(
            "  of which ray casting (numba)",
            n,
            t_cast,
            f"{len(world.static.segments)} segments, {len(world.static.circles) + circles.shape[1]} circles",
        ),
        Row("ground truth CDR encoding", n, t_gt, "for the log writer"),
        Row("write the log (scans + ground truth MCAP)", n, t_write, "what datmo simulate adds"),
    ]
    print_table("Simulator, hall scene", rows)
    print_lines("Simulator targets", [f"hall at 361 beams: {n / t_sim:,.0f} scans/s (target >= 2,000)"])


if __name__ == "__main__":
    main()
