#!/usr/bin/env bash
# Runs ruff (lint, import order, banned APIs) and the test suite, installing first if needed.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/ruff check --quiet --no-cache glsynth model tests bench
# One worker per core, at most 4 (a worker that opens a paper environment holds 4.5 GB);
# GLSYNTH_TEST_WORKERS=0 runs in this process (for a debugger or --pdb). tests/conftest.py groups
# the tests (a file, or all the tests of one generated dataset) that a worker runs together.
workers=${GLSYNTH_TEST_WORKERS:-$(( $(nproc) < 4 ? $(nproc) : 4 ))}
exec .venv/bin/python -m pytest -q -n "$workers" --dist loadgroup "$@"
