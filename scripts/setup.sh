#!/usr/bin/env bash
# Sets glsynth up on a fresh Debian machine (as root) and runs the main job on the small built-in
# default (the demo preset). Outputs go to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/glsynth export --preset demo --seed 0 --env 0 --out out/demo/scene.glb
.venv/bin/glsynth histograms --preset demo --seed 0 --count 200 --out out/demo/trajectories.png
.venv/bin/glsynth preview --preset demo --seed 0 --env 0 --out out/demo/preview.png
