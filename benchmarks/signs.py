"""Whether the rendered verdict on budgeted policies against `colmap-b` points the same way
as on photographs (issue 40): for each dataset, against the rendered regime nearest its
view count, each budgeted policy minus `colmap-b` in sfm mAA and pairs AUC@10 at each
budget: on the renders (pooled over scenes, the stratified 95% interval of the tables,
`bench.report.stats`), on the photographs (one run: a difference, no interval), and
whether their signs agree where the rendered interval excludes 0 and the photographs'
difference is not 0. With Kendall's tau of the two rankings (`bench.report.transfer`).

    .venv/bin/python benchmarks/signs.py --dataset-results results/datasets \
        --rendered results/published --rendered results/published-dense [--budget 256,512]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from bench.binding import read_settings, read_vocabulary
from bench.report.stats import paired_difference
from bench.report.tables import headline_frame, solvable
from bench.report.transfer import transfer_regimes
from bench.results import RUNS
from bench.runs import read_runs

PEER = "colmap-b"
METRICS = ("sfm_maa", "pairs_auc_10")


def differences(folder: Path, budget: int, metric: str) -> pd.DataFrame:
    """Per budgeted policy of a rendered folder: its mean difference to `PEER` over the
    units both ran, with the stratified interval."""
    vocab = read_vocabulary(folder)
    frame = headline_frame(read_runs(folder / RUNS), vocab)
    part = solvable(frame, metric, vocab)
    part = part[part["budget"] == budget]
    wide = part.pivot(index=["scene", "seed"], columns="method", values=metric).astype(float)
    scenes = wide.index.get_level_values("scene").to_numpy()
    out = {}
    for p in (m for m in vocab.with_role("baseline", "contender") if m in wide):
        if PEER in wide:
            r = paired_difference(wide[p] - wide[PEER], scenes, False)
            out[p] = (r["mean_diff"], r["lo"], r["hi"])
    return pd.DataFrame(out, index=["diff", "lo", "hi"]).T


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset-results", type=Path, required=True)
    ap.add_argument("--rendered", type=Path, action="append", required=True)
    ap.add_argument("--budget", default="256,512")
    args = ap.parse_args()
    budgets = [int(b) for b in args.budget.split(",")]
    rows = read_runs(args.dataset_results / RUNS)
    vocab = read_vocabulary(args.dataset_results)
    summary, _ = transfer_regimes(rows, vocab, args.rendered)
    photos = headline_frame(rows, vocab, dataset=True)
    views = {read_settings(r)["render"]["views"]: r for r in args.rendered}
    for (dataset, regime), taus in summary[summary["matched"]].groupby(
        ["dataset", "rendered_views"]
    ):
        rendered = views[regime]
        print(f"\n## {dataset}: against {rendered} ({regime} views)\n")
        for metric in METRICS:
            for budget in budgets:
                tau = taus[(taus["metric"] == metric) & (taus["budget"] == budget)]
                t = tau.iloc[0] if len(tau) else None
                tau_text = (
                    f"{t['kendall_tau']:.2f} [{t['tau_lo']:.2f}, {t['tau_hi']:.2f}]"
                    if t is not None and np.isfinite(t["kendall_tau"])
                    else "n/a"
                )
                ren = differences(rendered, budget, metric)
                print(f"{metric} @{budget}: tau {tau_text}")
                print("| policy | rendered - colmap-b | photographs - colmap-b | signs |")
                print("|---|---|---|---|")
                agree = disagree = 0
                for p in ren.index:
                    d, lo, hi = ren.loc[p]
                    ph = _photo(photos, dataset, p, budget, metric)
                    if not np.isfinite(ph):
                        continue
                    decided = np.isfinite(lo) and (lo > 0 or hi < 0) and ph != 0
                    same = decided and np.sign(d) == np.sign(ph)
                    agree, disagree = agree + same, disagree + (decided and not same)
                    mark = ("agree" if same else "DISAGREE") if decided else "-"
                    print(f"| {p} | {d:+.2f} [{lo:+.2f}, {hi:+.2f}] | {ph:+.2f} | {mark} |")
                print(f"signs decided: {agree} agree, {disagree} disagree\n")


def _photo(frame: pd.DataFrame, dataset: str, policy: str, budget: int, metric: str) -> float:
    """A dataset's policy minus `PEER` (one run; `frame`: the datasets' headline frame)."""
    at = frame[(frame["scene"] == dataset) & (frame["budget"] == budget)].set_index("method")
    if policy not in at.index or PEER not in at.index:
        return float("nan")
    return float(at.loc[policy, metric] - at.loc[PEER, metric])


if __name__ == "__main__":
    main()
