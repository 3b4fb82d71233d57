"""Labelled leg recordings from datmo's simulator, for training the leg detector beside real labelled scans.

The simulator knows every leg's centre (GroundTruth left/right leg, sensor frame, metres), so its scans are
exactly labelled. They teach the detector the LMS200's geometry (0.5° and 1° steps, legs of the paper's
10 cm radius at 1-8 m) that the real training bags (a 0.35° Hokuyo within about 5 m) lack. The scenes and
seeds below are never those of sample_logs/ (seed 1), so the sample logs stay held out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..log.vocabulary import CLASS_PERSON

# (scene, seed, people or None, resolution in degrees, duration in s)
SIMULATED = (("crowd", 11, 6, 0.5, 60.0), ("crowd", 12, 8, 1.0, 60.0), ("corridor", 13, None, 0.5, 60.0),
             ("crowd", 14, 4, 0.5, 30.0))


def simulated_recording(scene: str, seed: int, people: int | None = None, resolution: float = 0.5,
                        duration: float = 60.0):
    """One simulated LMS200 recording with every visible person's two leg centres as its labels."""
    from ..sim.simulate import simulate_scene
    from .training import Recording

    sim = simulate_scene(scene, seed=seed, duration=duration, people=people, resolution_deg=resolution)
    legs = []
    for k in range(len(sim.run)):
        o = sim.truth[sim.truth_offsets[k]:sim.truth_offsets[k + 1]]
        o = o[(o["classification"] == CLASS_PERSON) & (o["visible"] == 1)]
        left = np.stack([o["left_leg_x"], o["left_leg_y"]], axis=1)
        right = np.stack([o["right_leg_x"], o["right_leg_y"]], axis=1)
        legs.append(np.concatenate([left, right]).astype(np.float64).reshape(-1, 2))
    name = f"simulated {scene} seed {seed}" + (f" {people} people" if people else "") + f" {resolution:g}°"
    return Recording(name, Path(f"simulated/{scene}-{seed}"), "/scan", sim.run, legs)


def simulated_recordings() -> list:
    """The SIMULATED recordings (about 1,000 scans; a second or two to simulate)."""
    return [simulated_recording(*spec) for spec in SIMULATED]
