"""Whether two runs of one grid on two machines rank the methods alike (issue 47/48).

Renders differ in their last bits between machines (a CUDA and an LLVM variant, say), and
every row downstream moves with them. For each task's first headline metric (tri
completeness, sfm mAA, pairs AUC@10) under the headline protocol, on the (scene, seed, method,
budget) cells both runs hold: the share of identical cells, and Kendall's tau-b of the
(method, budget) means of one run against the other's (the figure issue 48 quotes: 0.79 in
sfm for the dense regime, a GPU run against the CPU rows), and per budget.

    .venv/bin/python benchmarks/machines.py results/published OTHER_RESULTS_DIR
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.binding import read_vocabulary
from bench.report.power import tau
from bench.report.tables import headline_frame, solvable
from bench.runs import read_runs

METRICS = {"tri": "acc_completeness_pct", "sfm": "sfm_maa", "pairs": "pairs_auc_10"}


def cells(folder: Path, metric: str):
    vocab = read_vocabulary(folder)
    frame = headline_frame(read_runs(folder / "runs.csv"), vocab)
    if metric not in frame:
        return None
    rows = solvable(frame, metric, vocab)
    rows = rows[(rows["budget"] > 0) & ~rows["method"].isin(["oracle", "all", "colmap"])]
    return rows.set_index(["scene", "seed", "method", "budget"])[metric].dropna()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs=2, type=Path, help="two results folders of one grid")
    a_dir, b_dir = ap.parse_args().results
    for task, metric in METRICS.items():
        a, b = cells(a_dir, metric), cells(b_dir, metric)
        if a is None or b is None:
            continue
        a, b = a.align(b, join="inner")
        same = float(np.mean(np.isclose(a, b, rtol=0, atol=1e-9)))
        ma, mb = (x.groupby(["method", "budget"]).mean() for x in (a, b))
        per = [
            f"B={bud} {tau(ma.xs(bud, level='budget'), mb.xs(bud, level='budget')):.2f}"
            for bud in sorted(set(ma.index.get_level_values("budget")))
        ]
        print(
            f"{task} {metric}: {len(a)} common cells, {same:.0%} identical; tau over "
            f"(method, budget) {tau(ma, mb):.2f}; " + ", ".join(per)
        )


if __name__ == "__main__":
    main()
