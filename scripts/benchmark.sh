#!/usr/bin/env bash
# Set everything up, then run the full benchmark (arguments go to `bench run`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/bench run "$@"
