#!/usr/bin/env bash
# Runs ruff (lint, import order, banned APIs) and the test suite, installing first if needed.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
.venv/bin/ruff check --quiet --no-cache glsynth model tests bench
exec .venv/bin/python -m pytest -q "$@"
