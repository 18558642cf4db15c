"""The metric columns of two runs.csv files compared on their common rows (timings, hashes,
checksums and invocations left out): how many values differ exactly and beyond 1e-6 relative.

    .venv/bin/python benchmarks/compare_runs.py results/published/runs.csv results/latest/runs.csv
"""

import argparse

import numpy as np
import pandas as pd

KEY = ["scene", "seed", "method", "budget", "task", "protocol"]
ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("runs", nargs=2, metavar="RUNS_CSV", help="the two runs.csv files")
a, b = (pd.read_csv(p, keep_default_na=False, na_values=[""]) for p in ap.parse_args().runs)
skip = {
    "render_key",
    "config_hash",
    "prediction_hash",
    "evaluation_hash",
    "invocation",
    "row_checksum",
    "wall_ms",
    "render_s_per_view",
}
skip |= {c for c in set(a) | set(b) if c.endswith("_ms")}
a, b = a.set_index(KEY).sort_index(), b.set_index(KEY).sort_index()
common = a.index.intersection(b.index)
print(f"rows: {len(a)} vs {len(b)}, common {len(common)}")
cols = [c for c in a.columns if c in b.columns and c not in skip]
only = sorted((set(a.columns) ^ set(b.columns)) - skip)
print("columns compared:", len(cols), "not in both:", only)
bad = 0
for c in cols:
    x, y = a.loc[common, c], b.loc[common, c]
    if x.dtype.kind in "fi" and y.dtype.kind in "fi":
        same = np.isclose(x.astype(float), y.astype(float), rtol=0, atol=0, equal_nan=True)
        close = np.isclose(x.astype(float), y.astype(float), rtol=1e-6, atol=0, equal_nan=True)
        if not same.all():
            print(
                f"  {c}: {int((~same).sum())} differ exactly, {int((~close).sum())} beyond 1e-6 relative"
            )
            bad += int((~close).sum())
    else:
        d = x.fillna("").astype(str) != y.fillna("").astype(str)
        if d.any():
            print(f"  {c}: {int(d.sum())} differ; e.g. {x[d].iloc[0]!r} vs {y[d].iloc[0]!r}")
            bad += int(d.sum())
print("DIFFERENCES beyond 1e-6:", bad)
