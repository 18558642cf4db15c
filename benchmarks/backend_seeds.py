"""Does averaging the sfm task over back-end seeds narrow a paired interval at a small
budget, for its cost? (issue 62, item 5; docs/matchability.md, "Back-end seeds at 128").

At 128 a sparse cell's sfm mAA is mostly the back end's chance (COLMAP's RANSAC and its
mapper, seeded by `backend.seed`). Each folder is one sparse run at one back-end seed, the
same scenes, seeds and methods:

    for s in 1 2 3 4; do .venv/bin/bench run --regime sparse --budget 128 --tasks sfm \\
        --protocols multiview --methods matchable,colmap-b,octave-scale \\
        --set backend.seed=$s --results /work/scratch/seed$s; done
    .venv/bin/python benchmarks/backend_seeds.py results/published /work/scratch/seed{1..4}

It prints, for each pair of methods, the paired difference's stratified 95 % interval
(`bench.report.stats.paired_difference`) from each back-end seed alone and from each
cell's mean over the seeds, with the mean within-cell standard deviation over the seeds.
The cells are those stock COLMAP maps at every seed (the verdicts' exclusion rule, held at
each seed).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from bench.report.stats import paired_difference
from bench.runs import read_runs

PAIRS = (("matchable", "colmap-b"), ("octave-scale", "colmap-b"), ("matchable", "octave-scale"))


def sfm_at(folder: Path, budget: int) -> tuple[pd.DataFrame, pd.Series]:
    """The sfm mAA (multiview) per (scene, seed) and method at `budget`, and whether stock
    COLMAP maps each cell."""
    runs = read_runs(folder / "runs.csv")
    rows = runs[(runs["task"] == "sfm") & (runs["protocol"] == "multiview")]
    maps = rows.groupby(["scene", "seed"])["reference_maps"].first().ne(0)
    wide = rows[rows["budget"] == budget].pivot_table(
        index=["scene", "seed"], columns="method", values="maa"
    )
    return wide, maps


def line(name: str, d: pd.Series) -> str:
    """A paired difference and its interval, one line."""
    r = paired_difference(d, d.index.get_level_values("scene"), False)
    half = (r["hi"] - r["lo"]) / 2
    return (
        f"    {name:<22} {r['mean_diff']:+.3f} [{r['lo']:+.3f}, {r['hi']:+.3f}] "
        f"(+/-{half:.3f}), {r['wins']}/{r['ties']}/{r['losses']} over {r['n']} cells"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("folders", nargs="+", type=Path, help="one sparse run per back-end seed")
    ap.add_argument("--budget", type=int, default=128)
    args = ap.parse_args()
    runs = [sfm_at(f, args.budget) for f in args.folders]
    cells = runs[0][1].index
    for _, maps in runs:
        cells = cells[maps.reindex(cells, fill_value=False).to_numpy()]
    print(f"{len(cells)} cells mapped by stock COLMAP at all {len(runs)} back-end seeds")
    for a, b in PAIRS:
        print(f"  {a} - {b}, sfm mAA at {args.budget}:")
        diffs = [(w[a] - w[b]).reindex(cells) for w, _ in runs]
        for f, d in zip(args.folders, diffs):
            print(line(f"one seed ({f.name})", d))
        stacked = pd.concat(diffs, axis=1)
        print(line(f"mean of {len(runs)} seeds", stacked.mean(axis=1)))
        spread = [np.mean([w[m].reindex(cells) for w, _ in runs], axis=0) for m in (a, b)]
        std = {
            m: pd.concat([w[m].reindex(cells) for w, _ in runs], axis=1).std(axis=1, ddof=1)
            for m in (a, b)
        }
        print(
            f"    within-cell std over seeds: {a} {std[a].mean():.3f}, {b} {std[b].mean():.3f}; "
            f"means {spread[0].mean():.3f}, {spread[1].mean():.3f}"
        )


if __name__ == "__main__":
    main()
