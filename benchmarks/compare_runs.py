"""The metric columns of two runs.csv files compared on their common rows, exactly
(timings, hashes, checksums and invocations left out; `bench.report.compare`).

    .venv/bin/python benchmarks/compare_runs.py results/published/runs.csv results/latest/runs.csv
"""

import argparse
import sys

from bench.report.compare import compare_rows
from bench.runs import read_runs

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("runs", nargs=2, metavar="RUNS_CSV", help="the two runs.csv files")
a, b = (read_runs(p) for p in ap.parse_args().runs)
result = compare_rows(a, b)
print("\n".join(result.lines()))
sys.exit(1 if result.moved else 0)
