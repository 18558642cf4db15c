"""Wall-clock of the same `bench run` with different worker counts, same machine, same
caches (render and front-end caches warm: run the command once first), each into a fresh
results folder; prints seconds per worker count and the speed-up over the first.

    .venv/bin/python benchmarks/workers_speed.py --workers 1,2 [-- extra bench run args]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("--workers", default="1,2", help="comma-separated worker counts")
ap.add_argument("extra", nargs="*", help="arguments passed to `bench run` (after --)")
a = ap.parse_args()
bench = Path(sys.executable).with_name("bench")
seconds = {}
with tempfile.TemporaryDirectory() as tmp:
    for w in a.workers.split(","):
        cmd = [str(bench), "run", "--workers", w, "--results", f"{tmp}/w{w}", *a.extra]
        t = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        seconds[w] = time.perf_counter() - t
        print(f"workers {w}: {seconds[w]:.1f} s", flush=True)
first = next(iter(seconds.values()))
for w, s in seconds.items():
    print(f"workers {w}: speed-up {first / s:.2f}x over workers {next(iter(seconds))}")
