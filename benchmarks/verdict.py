"""The numbers issue 28 asks for, from the `runs.csv` of one or more results folders (one
per rig regime), nothing recomputed; the headline protocol (`multiview`) only:

- `colmap` and `all` (stock COLMAP, the whole SIFT pool): sfm mAA and registered views per
  scene and seed;
- the share of the budgeted policies' sfm cells (scene, seed) with mAA at or below 0.05,
  per budget, per scene and pooled;
- `pairs` AUC@10 of the paper's four policies, each pair's difference A - B with the
  tables' stratified 95% t-interval (`bench.report.stats`), pooled over scenes, per budget.

    .venv/bin/python benchmarks/verdict.py results/published results/published-dense
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import pandas as pd

from bench.report.stats import paired_difference

PAPER = ["adaptive", "texture", "grid", "random"]
PEERS = ["colmap", "all"]
ZERO = 0.05


def peers(runs: pd.DataFrame) -> str:
    """`colmap` and `all`: sfm mAA (registered views) per scene, seeds in order."""
    sfm = runs[(runs["task"] == "sfm") & runs["method"].isin(PEERS)].sort_values("seed")
    lines = []
    for (scene, method), g in sfm.groupby(["scene", "method"]):
        cells = ", ".join(f"{m:.2f} ({v:.0f})" for m, v in zip(g["maa"], g["registered_views"]))
        lines.append(f"  {scene:<11} {method:<7} {cells}")
    return "\n".join(lines)


def zero_shares(runs: pd.DataFrame) -> str:
    """Share of budgeted sfm cells at mAA <= ZERO, per budget: per scene and pooled."""
    sfm = runs[(runs["task"] == "sfm") & (runs["budget"] > 0) & (runs["method"] != "oracle")]
    sfm = sfm[~sfm["method"].str.startswith("colmap")]  # the peers held to the budget
    lines = []
    for budget, g in sfm.groupby("budget"):
        zero = g["maa"].fillna(0) <= ZERO
        per = zero.groupby(g["scene"]).mean()
        scenes = ", ".join(f"{s} {100 * v:.0f}" for s, v in per.items())
        lines.append(
            f"  B = {budget}: {100 * zero.mean():.0f} % ({zero.sum()}/{len(zero)}, "
            f"{g['method'].nunique()} policies); {scenes}"
        )
    return "\n".join(lines)


def pairs_differences(runs: pd.DataFrame) -> str:
    """AUC@10 of the pairs task, A - B for each pair of PAPER, stratified by scene."""
    rows = runs[(runs["task"] == "pairs") & runs["method"].isin(PAPER)]
    lines = []
    for budget, g in rows.groupby("budget"):
        wide = g.pivot_table(index=["scene", "seed"], columns="method", values="auc_10")
        cells = []
        for a, b in itertools.combinations(PAPER, 2):
            d = paired_difference(wide[a] - wide[b], wide.index.get_level_values("scene"), False)
            mean, lo, hi, note = d["mean_diff"], d["lo"], d["hi"], d["note"]
            sep = "*" if lo > 0 or hi < 0 else ""
            interval = note or f"[{lo:+.2f}, {hi:+.2f}]{sep}"
            cells.append(f"{a}-{b} {mean:+.2f} {interval}")
        n = len(wide)
        lines.append(f"  B = {budget} ({n} units): " + "; ".join(cells))
    return "\n".join(lines) + "\n  (* the interval excludes 0)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("results", nargs="+", type=Path, help="results folders holding runs.csv")
    args = ap.parse_args()
    for folder in args.results:
        runs = pd.read_csv(folder / "runs.csv")
        runs = runs[runs["protocol"] == "multiview"]
        seeds = ",".join(str(s) for s in sorted(runs["seed"].unique()))
        views = ",".join(str(v) for v in sorted(runs["views"].unique()))
        print(f"{folder} ({views} views, seeds {seeds})")
        print(" sfm mAA (registered views) of the stock peers, seeds in order:")
        print(peers(runs))
        print(f" budgeted sfm cells at mAA <= {ZERO}:")
        print(zero_shares(runs))
        print(" pairs AUC@10, pooled over scenes:")
        print(pairs_differences(runs))


if __name__ == "__main__":
    main()
