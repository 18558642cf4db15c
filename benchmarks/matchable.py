"""The paired differences issue 62 asks for, from the `runs.csv` of results folders,
nothing recomputed: `matchable` minus each peer (`colmap-b`, `octave-scale`, `aliked-b`
where it ran), per budget, in sfm mAA (the headline `multiview` protocol; on rendered
scenes the cells where stock COLMAP maps, as the verdicts take them; a dataset's all) and pairs AUC@10, each with the
tables' stratified 95 % interval (`bench.report.stats.paired_difference`) and wins / ties
/ losses; and the seconds `matchable` took to select, per view.

    .venv/bin/python benchmarks/matchable.py results/published results/published-dense \
        results/published-datasets
    .venv/bin/python benchmarks/matchable.py results/published --peers ALIKED_FOLDER
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from bench.report.stats import paired_difference
from bench.runs import read_runs

POLICY = "matchable"
PEERS = ("colmap-b", "octave-scale", "aliked-b")
METRICS = {"sfm": "maa", "pairs": "auc_10"}


def differences(runs: pd.DataFrame) -> list[str]:
    """One line per task, budget and peer."""
    lines = []
    for task, metric in METRICS.items():
        rows = runs[runs["task"] == task]
        if task == "sfm":
            rows = rows[rows["protocol"] == "multiview"]
            rendered = rows["ground_truth"].str.startswith("rendered")
            rows = rows[rows["reference_maps"].ne(0) | ~rendered]
        for budget, g in rows[rows["budget"] > 0].groupby("budget"):
            wide = g.pivot_table(index=["scene", "seed"], columns="method", values=metric)
            if POLICY not in wide:
                continue
            for peer in (p for p in PEERS if p in wide):
                d = paired_difference(
                    wide[POLICY] - wide[peer], wide.index.get_level_values("scene"), False
                )
                interval = d["note"] or f"[{d['lo']:+.3f}, {d['hi']:+.3f}]"
                lines.append(
                    f"  {task:<5} B={budget:<4} {POLICY} {wide[POLICY].mean():.3f} - {peer} "
                    f"{wide[peer].mean():.3f} = {d['mean_diff']:+.3f} {interval} "
                    f"(+/-{(d['hi'] - d['lo']) / 2:.3f}), {d['wins']}/{d['ties']}/{d['losses']} "
                    f"over {d['n']} cells"
                )
    return lines


def select_seconds(runs: pd.DataFrame) -> str:
    """The milliseconds `matchable` and the peers' policies took to select, per view."""
    one = runs[(runs["budget"] > 0) & runs["method"].isin([POLICY, "octave-scale", "response"])]
    one = one.drop_duplicates(["scene", "seed", "method", "budget"])
    ms = (one["select_ms"] / one["views"]).groupby(one["method"]).median()
    return ", ".join(f"{m} {v:.0f} ms" for m, v in ms.items())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("results", nargs="+", type=Path, help="results folders holding runs.csv")
    ap.add_argument(
        "--peers",
        type=Path,
        help="a results folder of the same scenes and seeds on another pool, whose rows join "
        "each folder's (aliked-b runs on ALIKED's pool: bench run --detector aliked "
        "--methods aliked-b)",
    )
    args = ap.parse_args()
    extra = read_runs(args.peers / "runs.csv") if args.peers else None
    for folder in args.results:
        runs = read_runs(folder / "runs.csv")
        if extra is not None:
            joins = extra["method"].isin(PEERS) & ~extra["method"].isin(runs["method"])
            runs = pd.concat([runs, extra[joins]], ignore_index=True)
        print(f"{folder} ({runs['scene'].nunique()} scenes, {runs['seed'].nunique()} seeds)")
        print("\n".join(differences(runs)))
        print(f"  selection per view (median): {select_seconds(runs)}")


if __name__ == "__main__":
    main()
