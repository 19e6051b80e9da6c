#!/usr/bin/env bash
# glsynth on an NVIDIA GPU, unattended, in under 10 minutes: sets up from a fresh clone, checks
# that EGL draws on the GPU (and says which device), renders the paper preset there and on the
# CPU, compares labels and depth, reports samples per second, and times FCN58 training steps.
#
#     bash bench/gpu.sh [OUT]      # results in OUT (default out/gpu): gpu.json, gpu.log
#
# Refuses with one line, before installing anything, where no NVIDIA GPU is found.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/gpu}
if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L 2>/dev/null | grep -q '^GPU '; then
    echo "bench/gpu.sh: no NVIDIA GPU found (nvidia-smi lists none); run it on a machine with" \
         "an NVIDIA GPU, its driver and its EGL library" >&2
    exit 2
fi
mkdir -p "$out"
log="$out/gpu.log"
nvidia-smi -L | tee "$log"
# Blender and Chromium serve other benches and tests, not this one: skip their installs.
GLSYNTH_NO_BLENDER=1 GLSYNTH_NO_CHROMIUM=1 timeout 270 bash scripts/install.sh 2>&1 | tee -a "$log"
timeout 300 .venv/bin/python bench/bench_gpu.py --out "$out" 2>&1 | tee -a "$log"
echo "bench/gpu.sh: results in $out/gpu.json"
