"""Scene simulation: an LMS200 in a 2D world of walls, columns, benches, boxes, platforms and walking people.

- `simulate.simulate_scene` / `simulate.Simulation`: the public entry points (whole run, or streamed blocks).
- `scene`: TOML scene files (built-in ones in `scenes/`) validated into dataclasses.
- `world`: a scene made concrete (static geometry, movers as functions of time, ground-truth objects).
- `walking`, `paths`: the walking model of docs/method.md §6.1 and waypoint paths.
- `raycast` (+ `_kernels`): exact ray casting with occlusion; `sensor`: quantisation, codes and noise.
"""
