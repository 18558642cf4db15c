"""What each cache key's code covers: the modules of its import closure
(`bench.codehash.closure`), with their lines of code.

    .venv/bin/python benchmarks/hash_coverage.py
"""

import argparse

from bench.codehash import closure
from bench.frontend.stage import FRONTEND_CODE
from bench.harness.keys import PREDICTION_CODE, SCORING_CODE
from bench.render.entry import RENDER_CODE

argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args()
KEYS = {
    "prediction (every row)": PREDICTION_CODE,
    "evaluation": SCORING_CODE,
    "front end": FRONTEND_CODE,
    "render": RENDER_CODE,
    "COLMAP extraction cache": ("bench.backend.peers",),
}
for name, roots in KEYS.items():
    files = closure(roots)
    lines = sum(len(p.read_text().splitlines()) for p in files.values())
    print(f"{name}: {', '.join(roots)} -> {len(files)} modules, {lines} lines")
    print("  " + " ".join(m.removeprefix("bench.") for m in files))
