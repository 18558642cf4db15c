#!/usr/bin/env bash
# Set everything up, check lint and format, then run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
LEARNED=1 bash scripts/setup.sh
.venv/bin/ruff check bench tests benchmarks
.venv/bin/ruff format --check bench tests benchmarks
exec .venv/bin/python -m pytest "$@"
