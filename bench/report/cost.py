"""The cost of a selection, on the page (issue 53): what each method matched and the time it
took, beside what it scored.

`table_cost.csv`, per method and budget (the pose-free task's rows, `Vocabulary.posefree_task`,
under the headline protocol):

* `sees` (`bench.vocabulary.sees`);
* `first_pass_kpv`: the keypoints per view matched before choosing (`first_pass`): none
  for a selection that sees its own image; for one that reads a signal of other views,
  the geometry's first pass (`signals.first_pass` of `config.json`, the strongest
  candidates of every view matched in every pair); for a method with a first pass of its
  own (`first_pass` among its settings, `track-first`: that multiple of B; the peer
  `colmap-tracks-b`: `TRACKS_FIRST_PASS` x B; `adaptive-loop`: its own B each round) the
  larger of the two;
* `final_kpv`: the keypoints per view it kept (`keypoints_per_view` where the rows hold
  it, the peers' and the equal-count methods'; else the budget);
* `ms_per_view`: the front end and matching milliseconds per view of a run: detection,
  the signals it reads, its selection (with any first pass and its own matching) and the
  matching and verification of what it kept (`detect_ms + signals_ms + select_ms +
  match_ms + verify_ms`, those the rows hold), over the run's views, mean over runs;
* each ranking metric of the tasks the peers run (`sfm_maa`, `pairs_auc_10`), its mean.

`figure_cost.png`: those metrics against `ms_per_view` (log x axis), a point per method
and budget, each category of `sees` in its own marker, and each category's stock-COLMAP
peer (`FRONTIER_PEERS`: `colmap-b` for its own image, `colmap-tracks-b` for other views)
at every budget it ran drawn as a black line: that category's frontier. A regime's grid
runs the two peers at 1024 and 2048 besides its budgets (`FRONTIER_BUDGETS`), so each
frontier spans 128 to 2048 keypoints per view; those rows (`frontier_only`) enter this
table and figure alone. A method is worth its cost where it lies above its category's
frontier; with one budget a frontier is a point, and the figure says so.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from bench.report.categories import peer_metrics
from bench.report.figures import method_styles, plt, save
from bench.report.tables import solvable
from bench.vocabulary import (
    FRONTIER_PEERS,
    HEADLINE,
    MULTI_VIEW,
    TRACKS_FIRST_PASS,
    TRACKS_PEER,
    VIEW_SIGNALS,
    VIEWS,
    Vocabulary,
    equal_parts,
)

TIMED = ("detect_ms", "signals_ms", "select_ms", "match_ms", "verify_ms")
"""The front end and matching stages of a row (module docstring)."""
FRONTIER_STYLE = {"colmap-b": "k-", "colmap-tracks-b": "k--"}
"""Each frontier's line (`FRONTIER_PEERS`)."""


def frontier_only(df: pd.DataFrame) -> pd.Series:
    """The rows of a frontier peer at a budget where no other budgeted method ran (the
    frontiers' own budgets, `FRONTIER_BUDGETS`): the cost's alone, left out of every other
    table, figure and verdict."""
    budgeted = df["budget"] > 0
    others = set(df.loc[budgeted & ~df["method"].isin(FRONTIER_PEERS), "budget"])
    return budgeted & df["method"].isin(FRONTIER_PEERS) & ~df["budget"].isin(others)


def first_pass(method: str, budget: int, vocab: Vocabulary, settings: dict) -> float:
    """Keypoints per view `method` matched before choosing at `budget` (module docstring)."""
    if vocab.sees(method) != VIEWS or budget <= 0:
        return 0.0
    m = vocab.methods[method]
    own = (settings.get("methods") or {}).get(method, {}).get("first_pass")
    n = float(own * budget) if own else 0.0
    if m.kind == TRACKS_PEER:
        n = max(n, TRACKS_FIRST_PASS * budget)
    policy = equal_parts(method)[0] if "@" in method else method
    if vocab.methods.get(policy, m).kind == MULTI_VIEW:
        n = max(n, budget)
    if any(s in VIEW_SIGNALS for s in m.reads):
        n = max(n, float((settings.get("signals") or {}).get("first_pass", 0)))
    return n


def table_cost(df: pd.DataFrame, frame: pd.DataFrame, vocab: Vocabulary, settings: dict):
    """`table_cost.csv` (module docstring; `df`: the rows, `frame`: `headline_frame`)."""
    task = vocab.posefree_task
    if task is None or "views" not in df:
        return pd.DataFrame()
    rows = df[(df["task"] == task) & (df["protocol"] == HEADLINE[1]) & (df["budget"] > 0)]
    if rows.empty:
        return pd.DataFrame()
    timed = [c for c in TIMED if c in rows]
    ms = rows[timed].fillna(0).sum(axis=1) / rows["views"]
    kpv = rows["keypoints_per_view"] if "keypoints_per_view" in rows else rows["budget"] * math.nan
    rows = rows.assign(ms_per_view=ms, final_kpv=kpv.fillna(rows["budget"]))
    out = rows.groupby(["method", "budget"], sort=False)[["final_kpv", "ms_per_view"]].mean()
    out = out.reset_index()
    out.insert(1, "sees", out["method"].map(vocab.sees))
    first = [first_pass(m, b, vocab, settings) for m, b in zip(out["method"], out["budget"])]
    out.insert(3, "first_pass_kpv", first)
    for metric in (m for m in peer_metrics(vocab) if m in frame):
        means = solvable(frame, metric, vocab).groupby(["method", "budget"])[metric].mean()
        out[metric] = [means.get(k, math.nan) for k in zip(out["method"], out["budget"])]
    order = out.apply(lambda r: (r["budget"], vocab.order(r["method"])), axis=1)
    return out.loc[order.sort_values().index].reset_index(drop=True)


def figure_cost(cost: pd.DataFrame, vocab: Vocabulary, out: Path) -> bool:
    """`figure_cost.png` (module docstring); False (nothing drawn) without a ranking metric
    or a timed row."""
    metrics = [m for m in peer_metrics(vocab) if m in cost and cost[m].notna().any()]
    if not metrics or not (cost["ms_per_view"] > 0).any():
        return False
    fig, axes = plt.subplots(1, len(metrics), figsize=(7 * len(metrics), 5.5), squeeze=False)
    styles = method_styles(cost["method"], vocab)
    for ax, metric in zip(axes[0], metrics):
        for method, g in cost[cost[metric].notna()].groupby("method", sort=False):
            g = g.sort_values("budget")
            if method in FRONTIER_STYLE:
                label = f"{method} ({vocab.sees(method)} frontier"
                label += (
                    ")" if len(g) > 1 else f"; one budget, {int(g['budget'].iloc[0])}: a point)"
                )
                ax.plot(
                    g["ms_per_view"],
                    g[metric],
                    FRONTIER_STYLE[method],
                    marker="x",
                    lw=2,
                    label=label,
                )
                for k, (_, r) in enumerate(g.iterrows()):  # its name beside its largest
                    text = f"{int(r['budget'])}" + (f" {method}" if k == len(g) - 1 else "")
                    ax.annotate(text, (r["ms_per_view"], r[metric]), fontsize=7)
                continue
            ax.plot(
                g["ms_per_view"],
                g[metric],
                **styles[method],
                markersize=5,
                label=f"{method} ({vocab.sees(method)})",
            )
            last = g.iloc[-1]  # a direct label at its largest budget
            ax.annotate(
                method,
                (last["ms_per_view"], last[metric]),
                xytext=(3, 2),
                textcoords="offset points",
                fontsize=6,
                color=styles[method]["color"],
            )
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))  # 100, 200, 500, ...
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:,.0f}"))
        ax.xaxis.set_minor_formatter(NullFormatter())  # no label over another
        ax.set_xlabel("front end + matching ms per view (log)")
        ax.set_ylabel(metric)
        ax.set_title(f"{metric} against its cost, each budget a point")
        if np.isfinite(cost[metric]).any():
            ax.set_ylim(bottom=0)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.18, 1, 1))
    save(fig, out, ("png",))
    return True
