"""Whether the rendered ranking holds on photographs: `transfer.csv`,
`transfer_ranks.csv` and `figure_transfer.png` of a results folder of datasets.

For each dataset, budget, ranking metric (each task's first headline metric,
`bench.vocabulary.Task.headline`, named as in `paired.csv`: the `tri` task's
`acc_completeness_pct` where the dataset has per-pixel truth, the `sfm` task's `sfm_maa`)
and category of what a selection sees (`sees`: `image` or `views`; no ranking mixes the
two), the budgeted methods of the category that both results folders hold (at least 3;
a tau needs `MIN_METHODS`, 6) are ranked by their mean, best first
(by the metric's direction, `Task.lower_better`), on the dataset and on the rendered
benchmark (all its scenes and seeds pooled, at the same budget, under the headline
protocol; for a task with the exclusion rule, without the cells stock COLMAP does not map
where that rule holds, `bench.failures.exclusion_rule`; a dataset's cells are never left
out); tied means share their mean rank. `transfer.csv` has Kendall's tau-b between the
two rankings with a 95% percentile bootstrap interval (the methods resampled with
replacement, `DRAWS` draws, seed 0), the winner on each side and the methods whose rank
moves most; `transfer_ranks.csv` has every method's values and ranks. Below `MIN_METHODS`
methods there is no tau (with five methods, an exact permutation test at 5 % tells only a
perfect agreement or reversal from chance, with four or three not even that; with six, one
discordant pair too). A row without a tau says why in `tau_note`, and its verdict is
"cannot tell": too few methods, every method with the same mean on one side, or the
category's peer scoring 0 on the set (stock COLMAP makes nothing of it, as on forward
motion in bags for sfm).

Beside each tau, its power (`bench.report.power`, docs/protocol.md "Verdicts and their
power"): the split-half reliability of each side's ranking (`rel_rendered` over the rendered
(scene, seed) cells, `rel_dataset` over the dataset's bags), their `ceiling`, the
real-to-real baseline `tau_photos` (the other datasets' mean rank against this one; NaN
with one dataset), and the signs of each method minus its category's peer
(`SIGN_REFERENCES`) where both sides ran it: `signs_agree` of `signs_decided` between the renders and the dataset, beside
`signs_agree_photos` of `signs_decided_photos` between the other datasets' mean difference
and this one's.

Against several rendered folders (one per rig regime, `bench.cli.common.REGIMES`), the rows
of each carry its views per scene (`rendered_views`), and `matched` marks, per dataset, the
regime nearest the dataset's view count (ties: the denser): the comparison the README reports.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from bench.binding import read_settings, read_vocabulary
from bench.report.cost import frontier_only
from bench.report.power import ceiling, real_to_real, sign_agreement, split_half
from bench.report.tables import headline_frame, solvable
from bench.results import RUNS
from bench.runs import read_runs
from bench.vocabulary import IMAGE, VIEWS, Vocabulary

SIGN_REFERENCES = {IMAGE: "colmap-b", VIEWS: "colmap-tracks-b"}
"""Per category of `sees`, stock COLMAP's peer held to the budget: the signs of
`transfer.csv` are each method's minus it."""
DRAWS = 2000
MOVERS = 2
MIN_METHODS = 6
"""The fewest methods a ranking needs: below it there is no transfer row (module docstring)."""
MIN_RANKED = 3
"""The fewest methods a `transfer.csv` row is written for (without a tau below six)."""
NEEDS = f"a ranking needs at least {MIN_RANKED} methods, and a tau at least {MIN_METHODS}"
"""The one way the minimums are said (the run's log, `why_none`)."""
CANNOT_TELL = "cannot tell"
TRANSFER_TEXT = ("dataset", "metric", "tau_note", "winner_dataset", "winner_rendered")
TRANSFER_TEXT += ("biggest_movers",)
"""The text columns of `transfer.csv` (empty where a row has none; the rest are numbers)."""
"""The fewest budgeted methods both sides ran at a budget for a row of `transfer.csv`."""


def rendered_rows(rendered: Path) -> pd.DataFrame:
    """A rendered results folder's rows that rank methods: not the cost figure's frontier
    rows (`bench.report.cost.frontier_only`), which hold its peers alone."""
    rows = read_runs(Path(rendered) / RUNS)
    return rows[~frontier_only(rows)]


def kendall_tau(x: np.ndarray, y: np.ndarray) -> float:
    """Kendall's tau-b of two paired samples (NaN when either is constant)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    iu = np.triu_indices(len(x), 1)
    dx = np.sign(x[:, None] - x[None, :])[iu]
    dy = np.sign(y[:, None] - y[None, :])[iu]
    untied_x, untied_y = np.count_nonzero(dx), np.count_nonzero(dy)
    if not untied_x or not untied_y:
        return math.nan
    return float((dx * dy).sum() / math.sqrt(untied_x * untied_y))


def tau_interval(x: np.ndarray, y: np.ndarray, seed: int = 0) -> tuple[float, float]:
    """95% percentile bootstrap interval of `kendall_tau`, the pairs resampled."""
    rng = np.random.default_rng(seed)
    draws = [kendall_tau(x[i], y[i]) for i in rng.integers(0, len(x), (DRAWS, len(x)))]
    draws = np.array([d for d in draws if not math.isnan(d)])
    if not len(draws):
        return math.nan, math.nan
    lo, hi = np.percentile(draws, [2.5, 97.5])
    return float(lo), float(hi)


def _means(frame: pd.DataFrame, metric: str, vocab: Vocabulary) -> pd.DataFrame:
    """Mean of `metric` per budget and budgeted method over the cells that count for it
    (`solvable`; budget 0, a whole-pool method, has no budget to rank at)."""
    frame = solvable(frame, metric, vocab)
    rows = frame[(frame["budget"] > 0) & frame[metric].notna()]
    return rows.groupby(["budget", "method"])[metric].mean().unstack("method")


def _cells(frame: pd.DataFrame, metric: str, vocab: Vocabulary, budget: int) -> pd.DataFrame:
    """The values of `metric` at `budget` per (scene, seed) cell and method (`solvable`)."""
    rows = solvable(frame, metric, vocab)
    rows = rows[(rows["budget"] == budget) & rows[metric].notna()]
    return rows.pivot_table(index=["scene", "seed"], columns="method", values=metric)


def power(
    real: pd.DataFrame,
    ref: pd.DataFrame,
    sets: pd.DataFrame,
    dataset: str,
    methods: list[str],
    lower_better: bool,
    reference: str = SIGN_REFERENCES[IMAGE],
) -> dict:
    """The power fields of one comparison (module docstring): `real` and `ref` the cells x
    methods of the dataset and of the renders, `sets` every dataset's means (sets x
    methods) at the same budget and metric, the signs against `reference`."""
    rel_r = split_half(ref.reindex(columns=methods))[1]
    rel_d = split_half(real.reindex(columns=methods))[1]
    sets = sets.reindex(columns=methods).dropna(axis=1)
    base = real_to_real(sets, lower_better).get(dataset, math.nan) if len(sets) > 1 else math.nan
    out = {
        "rel_rendered": rel_r,
        "rel_dataset": rel_d,
        "ceiling": ceiling(rel_r, rel_d),
        "tau_photos": base,
    }
    if reference in methods:
        mine = _minus(real.reindex(columns=methods).mean(), reference)
        rendered = _minus(ref.reindex(columns=methods).mean(), reference)
        out["signs_agree"], out["signs_decided"] = sign_agreement(mine, rendered)
        if reference in sets and len(sets) > 1:
            others = sets.drop(index=dataset).apply(_minus, axis=1, reference=reference).mean()
            out["signs_agree_photos"], out["signs_decided_photos"] = sign_agreement(mine, others)
    return out


def _minus(means: pd.Series, reference: str) -> pd.Series:
    """Each method's mean minus `reference`'s."""
    return means.drop(reference) - means[reference]


def compare(dataset: pd.Series, rendered: pd.Series, lower_better: bool) -> tuple[dict, list]:
    """One ranking comparison: the methods' means on a dataset and on the rendered
    benchmark (indexed by method, the same methods) -> (the fields of its `transfer.csv`
    row from `methods` on, its `transfer_ranks.csv` rows from `method` on); rank 1 is the
    best by the metric's direction."""
    methods = list(dataset.index)
    x, y = dataset[methods].to_numpy(float), rendered[methods].to_numpy(float)
    sign = 1 if lower_better else -1
    rank_x = pd.Series(sign * x, index=methods).rank(method="average")
    rank_y = pd.Series(sign * y, index=methods).rank(method="average")
    shift = rank_x - rank_y
    movers = shift.abs().sort_values(ascending=False, kind="stable").index[:MOVERS]
    if len(methods) >= MIN_METHODS:
        tau, (lo, hi), note = kendall_tau(x, y), tau_interval(x, y), ""
        if math.isnan(tau):
            note = "no tau: every method has the same mean on one side"
    else:
        tau, lo, hi = math.nan, math.nan, math.nan
        note = (
            f"no tau: {len(methods)} methods, too few to tell agreement from chance "
            f"(at least {MIN_METHODS})"
        )
    row = {
        "methods": len(methods),
        "kendall_tau": tau,
        "tau_lo": lo,
        "tau_hi": hi,
        "tau_note": note,
        "winner_dataset": _winner(rank_x),
        "winner_rendered": _winner(rank_y),
        "biggest_movers": "; ".join(
            f"{m} rendered {rank_y[m]:g} -> set {rank_x[m]:g}" for m in movers if shift[m]
        ),
    }
    ranks = [
        {
            "method": m,
            "value_dataset": dataset[m],
            "value_rendered": rendered[m],
            "rank_dataset": rank_x[m],
            "rank_rendered": rank_y[m],
            "rank_shift": shift[m],
        }
        for m in methods
    ]
    return row, ranks


def transfer(
    dataset_rows: pd.DataFrame, vocab: Vocabulary, rendered: Path
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(`transfer.csv`, `transfer_ranks.csv`) of a dataset folder's rows (under their
    vocabulary) against the rendered results folder `rendered` (module docstring)."""
    mine = headline_frame(dataset_rows, vocab, dataset=True)
    theirs = headline_frame(rendered_rows(rendered), read_vocabulary(rendered))
    views = read_settings(rendered)["render"]["views"]
    summary, ranks = [], []
    for dataset, rows in mine.groupby("scene", sort=False):
        for metric in vocab.first_headline():
            if metric not in rows or metric not in theirs:
                continue
            real, ref = _means(rows, metric, vocab), _means(theirs, metric, vocab)
            every = {d: _means(r, metric, vocab) for d, r in mine.groupby("scene", sort=False)}
            for budget in real.index.intersection(ref.index):
                a, b = real.loc[budget].dropna(), ref.loc[budget].dropna()
                lower = metric in vocab.lower_better()
                common = [m for m in a.index if m in b.index]
                for sees in dict.fromkeys(vocab.sees(m) for m in common):  # a chooser: ''
                    methods = [m for m in common if vocab.sees(m) == sees]
                    reference = SIGN_REFERENCES.get(sees, "")
                    if len(methods) < MIN_RANKED:
                        continue
                    row, rows_ranked = compare(a[methods], b[methods], lower)
                    if not row["tau_note"] and reference in methods and a[reference] == 0:
                        row |= {"kendall_tau": math.nan, "tau_lo": math.nan, "tau_hi": math.nan}
                        row["tau_note"] = (
                            f"cannot tell: the category's peer `{reference}` scores 0 on the "
                            "set (stock COLMAP makes nothing of it), so its ranking measures "
                            "nothing"
                        )
                    sets = pd.DataFrame(
                        {d: m.loc[budget] for d, m in every.items() if budget in m.index}
                    ).T
                    cells = (
                        _cells(rows, metric, vocab, budget),
                        _cells(theirs, metric, vocab, budget),
                    )
                    row |= power(*cells, sets, dataset, methods, lower, reference)
                    key = {"dataset": dataset, "rendered_views": views, "sees": sees}
                    key |= {"metric": metric, "budget": int(budget)}
                    summary.append(key | row)
                    ranks += [key | r for r in rows_ranked]
    return pd.DataFrame(summary), pd.DataFrame(ranks)


def why_none(dataset_rows: pd.DataFrame, rendered: Sequence[Path]) -> str:
    """Why `transfer_regimes` gives no row: the budgets, or the budgeted methods at a
    budget, that the datasets' rows and the rendered folders' share."""

    def ran(rows: pd.DataFrame) -> dict[int, set[str]]:
        rows = rows[rows["budget"] > 0]
        return {int(b): set(g["method"]) for b, g in rows.groupby("budget")}

    mine = ran(dataset_rows)
    theirs = [ran(rendered_rows(r)) for r in rendered]
    shared = {b: mine[b] & t[b] for t in theirs for b in mine.keys() & t.keys()}
    if not shared:
        budgets = sorted({b for t in theirs for b in t})
        return (
            f"no budget (the datasets ran {', '.join(map(str, sorted(mine)))}; "
            f"the rendered results {', '.join(map(str, budgets))})"
        )
    b = max(shared, key=lambda k: len(shared[k]))
    return (
        f"at most {len(shared[b])} budgeted method(s) at one budget "
        f"({', '.join(sorted(shared[b]))} at {b}); {NEEDS}"
    )


def transfer_regimes(
    dataset_rows: pd.DataFrame, vocab: Vocabulary, rendered: Sequence[Path]
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """`transfer` against each rendered folder in turn, with `matched` (module docstring)."""
    parts = [transfer(dataset_rows, vocab, Path(r)) for r in rendered]
    summary = pd.concat([p[0] for p in parts], ignore_index=True)
    ranks = pd.concat([p[1] for p in parts], ignore_index=True)
    if summary.empty:
        return summary, ranks
    own = dataset_rows.groupby("scene")["views"].median()
    offered = set(summary["rendered_views"])
    nearest = {d: max(offered, key=lambda o: (-abs(o - v), o)) for d, v in own.items()}
    for frame in (summary, ranks):
        frame.insert(2, "matched", frame["rendered_views"] == frame["dataset"].map(nearest))
    return summary, ranks


def said(summary: pd.DataFrame, budget: int) -> list[str]:
    """Per dataset, one line of its matched regime's taus at `budget` (or why there are none)."""
    lines = []
    rows = summary[summary["matched"] & (summary["budget"] == budget)]
    for dataset, group in rows.groupby("dataset", sort=False):
        notes = set(group["tau_note"])
        taus = [
            f"{r.metric} (sees {r.sees}) "
            + (r.tau_note or f"{r.kendall_tau:.2f} [{r.tau_lo:.2f}, {r.tau_hi:.2f}]")
            for r in group.itertuples()
        ]
        views = group["rendered_views"].iloc[0]
        lines.append(
            f"{dataset} against the {views}-view regime at B = {budget}, Kendall's tau: "
            + (notes.pop() if len(notes) == 1 and "" not in notes else "; ".join(taus))
        )
    return lines


def verdicts(summary: pd.DataFrame, budget: int) -> list[str]:
    """Per dataset and ranking metric, one sentence at `budget` on its matched regime: what
    the tau says, the interval beside the ceiling the two rankings' reliabilities allow,
    and whether the renders predict the set as well as the other sets do (`tau_photos`)."""
    if "rel_rendered" not in summary:
        return []
    rows = summary[summary["matched"] & (summary["budget"] == budget)]
    return [_verdict(r, budget) for r in rows.itertuples()]


def _verdict(r, budget: int) -> str:
    """One row's sentence (`verdicts`)."""
    sees = getattr(r, "sees", "")
    among = f" among the selections that see `{sees}`" if isinstance(sees, str) and sees else ""
    head = (
        f"{r.dataset}, {r.metric}{among}, B = {budget}, against the {r.rendered_views}-view "
        "renders: "
    )
    cap = (
        f"the split-half reliabilities ({r.rel_rendered:.2f} renders, {r.rel_dataset:.2f} this "
        f"set) cap any tau at the ceiling {r.ceiling:.2f}"
        if not math.isnan(r.ceiling)
        else f"the split-half reliabilities ({_rel(r.rel_rendered)} renders, "
        f"{_rel(r.rel_dataset)} this set) allow no ceiling: a reliability at or below 0 "
        "means the two halves of its cells rank the methods no more alike than chance, so "
        "nothing can be told of this ranking"
    )
    if math.isnan(r.kendall_tau):
        note = r.tau_note if isinstance(r.tau_note, str) and r.tau_note else "no tau"
        return head + f"{note}; {cap}."
    said = (
        f"tau {r.kendall_tau:.2f} [{r.tau_lo:.2f}, {r.tau_hi:.2f}] (1: the renders order its "
        f"methods as the set does, 0: no relation, -1: reversed); {cap}"
    )
    if r.tau_hi > r.ceiling:
        said += " (the interval reaching above it is the bootstrap's spread over methods)"
    photos = getattr(r, "tau_photos", math.nan)
    if math.isnan(photos):
        return head + said + "; no other set to compare with (the baseline needs two sets)."
    how = prediction(r)
    if how == CANNOT_TELL:
        return head + said + f"; the other sets predict it at {photos:.2f}: {CANNOT_TELL}."
    inside = " (theirs lies within the interval)" if how == AS_WELL else ""
    return (
        head + said + f"; the other sets predict it at {photos:.2f}: the renders predict it "
        f"{how} the other photographs{inside}."
    )


AS_WELL = "as well as"


def _rel(x: float) -> str:
    return "undefined" if math.isnan(x) else f"{x:.2f}"


def prediction(r) -> str:
    """Whether the renders predict a set's ranking (a `transfer.csv` row) as well as the
    other sets do: `AS_WELL`, "less well than" or "better than", told apart only where the
    other sets' tau lies outside the interval of the renders' tau; `CANNOT_TELL` where the
    ranking has no tau or no ceiling (a reliability at or below 0, a peer that maps
    nothing); "n/a" without another set to compare with."""
    photos = getattr(r, "tau_photos", math.nan)
    if math.isnan(r.kendall_tau) or math.isnan(getattr(r, "ceiling", 0.0)):
        return CANNOT_TELL
    if math.isnan(photos):
        return "n/a"
    if photos > r.tau_hi:
        return "less well than"
    return "better than" if photos < r.tau_lo else AS_WELL


def _winner(rank: pd.Series) -> str:
    """The best-ranked method(s), ties joined with '='."""
    return "=".join(rank[rank == rank.min()].index)
