#!/usr/bin/env bash
# Sets glsynth up on a fresh Debian machine (as root) and runs the main job on the small built-in
# default: the demo dataset (3 environments x 12 cameras + 12 plates, Tokaido layout) in
# out/demo/dataset, plus a preview sheet and one exported environment. A second run resumes
# (and finds nothing left to do).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/glsynth generate --preset demo --seed 0 --out out/demo/dataset
.venv/bin/glsynth preview --preset demo --seed 0 --env 0 --out out/demo/preview.png
.venv/bin/glsynth export --preset demo --seed 0 --env 0 --out out/demo/scene.glb
