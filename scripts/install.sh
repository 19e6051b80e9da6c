#!/usr/bin/env bash
# Installs what glsynth needs on a Debian machine (run as root): Mesa's EGL and OSMesa, a virtual
# environment in .venv with the project, torch==2.13.0 and the test tools. Idempotent: a second
# run with an unchanged pyproject.toml returns at once.
set -euo pipefail
cd "$(dirname "$0")/.."

# GL: EGL (default) and OSMesa (fallback) from Mesa; libxrender1 because pyrender imports pyglet;
# jemalloc for full-resolution training (docs/design.md, "Training memory").
system_packages=(libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libosmesa6 libxrender1
                 libjemalloc2)
command -v python3 >/dev/null || system_packages+=(python3)
python3 -c 'import ensurepip, venv' 2>/dev/null || system_packages+=(python3-venv)
missing=()
for pkg in "${system_packages[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" \
        || missing+=("$pkg")
done
export DEBIAN_FRONTEND=noninteractive
if [ ${#missing[@]} -gt 0 ]; then
    echo "installing system packages: ${missing[*]}"
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

stamp=.venv/.glsynth-install
want=$(cat pyproject.toml scripts/install.sh | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi
# Optional: Blender, with the numpy its glTF importer needs, for `glsynth bench blender` and its
# test (about 90 MB). GLSYNTH_NO_BLENDER=1 skips it; if it cannot be installed, only that bench
# and test are skipped. Tried once per install (behind the stamp), not on every test run.
if [ -z "${GLSYNTH_NO_BLENDER:-}" ] && ! command -v blender >/dev/null; then
    echo "installing Blender (optional; GLSYNTH_NO_BLENDER=1 skips it)"
    { apt-get update -qq && apt-get install -y -qq --no-install-recommends blender python3-numpy; } \
        >/dev/null 2>&1 || echo "note: could not install Blender; glsynth bench blender will skip"
fi

# Optional: Debian's Chromium and its WebDriver, for the viewer's browser tests (about 100 MB).
# GLSYNTH_NO_CHROMIUM=1 skips it; without it those tests skip. Tried once, like Blender.
if [ -z "${GLSYNTH_NO_CHROMIUM:-}" ] && ! command -v chromedriver >/dev/null; then
    echo "installing Chromium (optional; GLSYNTH_NO_CHROMIUM=1 skips it)"
    { apt-get update -qq && apt-get install -y -qq --no-install-recommends chromium \
        chromium-driver; } >/dev/null 2>&1 \
        || echo "note: could not install Chromium; the viewer's browser tests will skip"
fi

[ -x .venv/bin/python ] || python3 -m venv .venv
# --no-compile: Python compiles a module's bytecode when it is first imported, so compiling
# every file of torch, scipy and ray up front (most never imported) only made the install
# slower (docs/results.md, "The test suite"). Where PYTHONDONTWRITEBYTECODE is set, or the
# environment is read-only, nothing is cached and each process compiles what it imports,
# every time; scripts/test.sh unsets it.
pip=(.venv/bin/python -m pip install -q --disable-pip-version-check --no-compile)
# torch first and pinned: a looser requirement would pull several GB of CUDA packages.
"${pip[@]}" "torch==2.13.0"
"${pip[@]}" -e ".[model,test,ray,bench,view,flights]"

# The Khronos glTF validator (a test checks exported scenes with it), when npm is available.
if command -v npm >/dev/null; then
    npm install --silent --no-audit --no-fund --prefix .tools gltf-validator@2.0.0-dev.3.10 \
        >/dev/null 2>&1 || echo "note: could not install gltf-validator; its test will skip"
fi
echo "$want" > "$stamp"
