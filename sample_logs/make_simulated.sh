#!/usr/bin/env bash
# Regenerate the simulated sample logs bit for bit (called by sample_logs/make.sh from the project root).
# Each is 60 s of an LMS200 at 5 Hz, 180°/0.5° (361 beams), 8 m range, mm units, 1 cm noise.
set -euo pipefail
cd "$(dirname "$0")/.."
datmo simulate --scene hall --seed 1 --duration 60 -o sample_logs/hall.mcap --force
datmo simulate --scene corridor --seed 1 --duration 60 -o sample_logs/corridor.mcap --force
datmo simulate --scene crowd --people 6 --seed 1 --duration 60 -o sample_logs/crowd6.mcap --force
datmo simulate --scene static --seed 1 --duration 60 -o sample_logs/static.mcap --force
datmo simulate --scene patrol --seed 1 --duration 60 -o sample_logs/patrol.mcap --force
