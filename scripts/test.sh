#!/usr/bin/env bash
# Set everything up, check lint and format, then run the test suite. No ruff cache: it is
# keyed on modification times, which a checkout or a touch can set back.
set -euo pipefail
cd "$(dirname "$0")/.."
LEARNED=1 bash scripts/setup.sh
.venv/bin/ruff check --no-cache bench tests benchmarks
.venv/bin/ruff format --no-cache --check bench tests benchmarks
exec .venv/bin/python -m pytest "$@"
