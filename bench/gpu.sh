#!/usr/bin/env bash
# glsynth on an NVIDIA GPU, unattended, in under 10 minutes: sets up from a fresh clone, checks
# that EGL draws on the GPU (and says which device), renders the paper and inspection presets
# there and on the CPU, compares labels, depth and crack widths, reports samples per second,
# and times FCN58 training steps.
#
#     bash bench/gpu.sh [OUT] [bench_gpu.py options]   # results in OUT (default out/gpu)
#
# OUT gets gpu.json and gpu.log. On a machine that cannot install (no network, no root), set
# GLSYNTH_PYTHON to an interpreter that already imports glsynth and a CUDA torch (a command on
# PATH, or a path from the repository root): the install is skipped. Where that machine has
# no Mesa for the CPU render, pass --cpu-reference with the folder that
# `bench_gpu.py --cpu-only` wrote elsewhere (docs/results.md, "On a GPU").
#
# Refuses with one line, before installing anything, where no NVIDIA GPU is found.
set -euo pipefail
cd "$(dirname "$0")/.."
out=out/gpu
if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then  # a first argument that is no option is OUT
    out=$1
    shift
fi
if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L 2>/dev/null | grep -q '^GPU '; then
    echo "bench/gpu.sh: no NVIDIA GPU found (nvidia-smi lists none); run it on a machine with" \
         "an NVIDIA GPU, its driver and its EGL library" >&2
    exit 2
fi
mkdir -p "$out"
log="$out/gpu.log"
nvidia-smi -L | tee "$log"
python=${GLSYNTH_PYTHON:-}
if [ -z "$python" ]; then
    # Blender and Chromium serve other benches and tests, not this one: skip their installs.
    GLSYNTH_NO_BLENDER=1 GLSYNTH_NO_CHROMIUM=1 timeout 270 bash scripts/install.sh 2>&1 \
        | tee -a "$log"
    python=.venv/bin/python
fi
timeout 300 "$python" bench/bench_gpu.py --out "$out" "$@" 2>&1 | tee -a "$log"
echo "bench/gpu.sh: results in $out/gpu.json"
