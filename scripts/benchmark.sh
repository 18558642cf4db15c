#!/usr/bin/env bash
# Set everything up, then run the full benchmark in each rig regime: sparse (6 views,
# seeds 0-4) -> results/latest/, dense (21 views, seeds 0,1) -> results/latest-dense/.
# Arguments go to both `bench run`s; REGIMES="sparse" runs one regime.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
for regime in ${REGIMES:-sparse dense}; do
    .venv/bin/bench run --regime "$regime" "$@"
done
