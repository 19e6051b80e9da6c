#!/usr/bin/env bash
# Runs ruff (lint, import order, banned APIs) and the test suite, installing first if needed.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/ruff check --quiet --no-cache glsynth model tests bench
# One worker per core, at most 4 (a worker that opens a paper environment holds 4.5 GB);
# GLSYNTH_TEST_WORKERS=0 runs in this process (for a debugger or --pdb). loadfile keeps a file's
# tests on one worker, so its module fixtures are made once. (Not loadgroup: with pytest 9.2,
# pytest-xdist 3.8 cannot rename a test's node id to carry its group, and loadgroup then spreads
# a file's tests over every worker, each making the file's fixtures again.) The files run in
# the order tests/conftest.py gives them (--no-loadscope-reorder), the slowest first.
# Bytecode caches on (some machines export PYTHONDONTWRITEBYTECODE): pytest then keeps each
# test file's rewritten asserts, and a worker collects in about 4 s instead of 8 from the
# second run on; every `glsynth` subprocess a test starts loads compiled modules. __pycache__
# is ignored by git.
unset PYTHONDONTWRITEBYTECODE
workers=${GLSYNTH_TEST_WORKERS:-$(( $(nproc) < 4 ? $(nproc) : 4 ))}
exec .venv/bin/python -m pytest -q -n "$workers" --dist loadfile --no-loadscope-reorder "$@"
