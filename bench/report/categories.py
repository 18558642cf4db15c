"""Verdicts per category (issue 53): what a selection sees decides whom it is judged
against. A selection that sees its own image (`sees` `image`, the field's rule) is judged
against the best own-image peer held to the budget, one that sees other views (`views`: a
first pass matched keypoints of every view) against `colmap-tracks-b`, stock COLMAP
choosing from its own first pass; no verdict ranks a method against one of the other
category without naming both.

`verdicts.csv` (`category_verdicts`): per budget, category and ranking metric (the first
headline metric of each task the peers run: `sfm_maa`, `pairs_auc_10`), the best policy
of the category (a baseline or contender, by its mean over the cells that count,
`bench.report.tables.solvable`) and the best peer of the category among those held to B
(`CATEGORY_PEERS`), their means and runs, and the paired difference policy minus peer over
the (scene, seed) units both have, with its 95% interval and wins/ties/losses
(`bench.report.stats.paired_difference`); `verdict` is `above` or `below` where the
interval excludes 0, else `tied`. `verdict_sentences` says each row in one sentence that
names its category; `headline` is the first sentence of the results page.
"""

from __future__ import annotations

import math

import pandas as pd

from bench.report.stats import paired_difference
from bench.report.tables import errored, solvable
from bench.report.text import ci
from bench.report.text import num as _num
from bench.vocabulary import CATEGORY_PEERS, HEADLINE_BUDGET, IMAGE, VIEWS, Vocabulary

CATEGORIES = {
    IMAGE: ("selections that see their own image", "the best own-image peer"),
    VIEWS: ("selections that see other views", "stock COLMAP choosing from its own first pass"),
}
"""Each category of `sees` that is judged, with how the page names it and its peer."""
POLICY_ROLES = ("baseline", "contender")
SHARED_MATCHES = (
    "in pairs, both the views selection and `colmap-tracks-b` have seen the scored pair's "
    "first-pass matches"
)
"""Said beside every pairs verdict of the `views` category."""


def members(vocab: Vocabulary, present, sees: str) -> tuple[list[str], list[str]]:
    """(the budgeted policies, the peers held to B) among `present` that see `sees`."""
    budgeted = [m for m in present if m in vocab.methods and not vocab.methods[m].whole_pool]
    same = [m for m in budgeted if vocab.sees(m) == sees]
    policies = [m for m in same if vocab.methods[m].role in POLICY_ROLES]
    return policies, [p for p in CATEGORY_PEERS if p in same]


def unjudged(vocab: Vocabulary, present) -> list[str]:
    """One line for each category whose budgeted policies ran without any of its peers:
    those policies are judged by no verdict, and the line names the peer to add."""
    out = []
    for sees in CATEGORIES:
        policies, peers = members(vocab, present, sees)
        wanted = [p for p in CATEGORY_PEERS if p in vocab.methods and vocab.sees(p) == sees]
        if policies and not peers and wanted:
            out.append(
                f"{', '.join(f'`{p}`' for p in sorted(policies, key=vocab.order))} (`{sees}`) "
                "judged by no verdict: no "
                f"peer of the category ran; add `{wanted[0]}` to --methods"
            )
    return out


def peer_metrics(vocab: Vocabulary) -> list[str]:
    """The first headline metric of each task the peers run, as the tables name them."""
    return [
        vocab.column(n, t.headline[0]) for n, t in vocab.tasks.items() if t.peers and t.headline
    ]


def _best(values: pd.DataFrame, methods: list[str], lower: bool) -> str:
    """The method of `methods` with the best mean, among those run on every cell any of
    them has: a method with fewer cells is never named best over cells it did not run."""
    counts = values.reindex(columns=methods).count()
    full = counts[(counts == counts.max()) & (counts > 0)].index
    means = values[list(full)].mean()
    if means.empty:
        return ""
    return str(means.idxmin() if lower else means.idxmax())


def category_verdicts(
    rows: pd.DataFrame, vocab: Vocabulary, method: str | None = None
) -> pd.DataFrame:
    """`verdicts.csv` (module docstring; `rows`: `headline_frame`); with `method`, that
    method against its category's peer, whichever method leads (`bench verdict`)."""
    out = []
    lower = vocab.lower_better()
    broken = errored(rows, vocab)  # a method that raised is judged by no verdict
    present = [m for m in pd.unique(rows["method"]) if m not in broken]
    for metric in (m for m in peer_metrics(vocab) if m in rows):
        counted = solvable(rows, metric, vocab)
        for budget in sorted(b for b in pd.unique(counted["budget"]) if b > 0):
            at = counted[counted["budget"] == budget]
            wide = at.pivot_table(index=["scene", "seed"], columns="method", values=metric)
            for sees in CATEGORIES:
                policies, peers = members(vocab, present, sees)
                if method is not None:
                    policies = [method] if method in policies else []
                policy, peer = (_best(wide, ms, metric in lower) for ms in (policies, peers))
                if not policy or not peer:
                    continue
                both = wide[[policy, peer]].dropna()  # the cells both have, and only those
                scenes = both.index.get_level_values("scene")
                res = paired_difference(both[policy] - both[peer], scenes, metric in lower)
                out.append(
                    {
                        "budget": budget,
                        "metric": metric,
                        "sees": sees,
                        "policy": policy,
                        "policy_mean": both[policy].mean(),
                        "policy_runs": int(wide[policy].count()),
                        "peer": peer,
                        "peer_mean": both[peer].mean(),
                        "peer_runs": int(wide[peer].count()),
                        **res,
                        "verdict": _verdict(res, metric in lower),
                    }
                )
    return pd.DataFrame(out)


def _verdict(res: dict, lower: bool) -> str:
    """`above`/`below` (the policy better/worse than the peer) where the interval excludes
    0, else `tied`."""
    lo, hi = res["lo"], res["hi"]
    if math.isnan(lo) or lo <= 0 <= hi:
        return "tied"
    return "below" if (lo > 0) == lower else "above"


def _three(x) -> str:
    """A mean in a sentence: three decimals, as the README's summary writes them."""
    return "n/a" if pd.isna(x) else f"{float(x):.3f}"


def _signed(x) -> str:
    """A paired difference or its bound: three decimals with its sign."""
    return "n/a" if pd.isna(x) else f"{float(x):+.3f}"


def verdict_sentence(r: pd.Series) -> str:
    """One verdict row as a sentence that names its category."""
    who, peer_is = CATEGORIES[r["sees"]]
    diff = ci(r["mean_diff"], r["lo"], r["hi"], r.get("note"), fmt=_signed)
    sentence = (
        f"Of the {who} (`{r['sees']}`), the best at B = {_num(r['budget'])} in "
        f"`{r['metric']}`, `{r['policy']}` ({_three(r['policy_mean'])}), against "
        f"{peer_is}, `{r['peer']}` ({_three(r['peer_mean'])}): {diff}, "
        f"{_num(r['wins'])}/{_num(r['ties'])}/{_num(r['losses'])} over {_num(r['n'])} "
        f"runs, {r['verdict']}"
    )
    if r.get("policy_runs", 0) != r.get("peer_runs", 0):  # the means and diff: common cells
        sentence += (
            f" (on the {_num(r['n'])} cells both ran: `{r['policy']}` {_num(r['policy_runs'])}, "
            f"`{r['peer']}` {_num(r['peer_runs'])})"
        )
    if r["sees"] == VIEWS and r["metric"].startswith("pairs_"):
        sentence += f" ({SHARED_MATCHES})"
    return sentence + "."


def verdict_sentences(verdicts: pd.DataFrame, budget: int | None = None) -> list[str]:
    """Every verdict row (at `budget` if given) as a sentence, metric by metric."""
    if verdicts.empty:
        return []
    rows = verdicts if budget is None else verdicts[verdicts["budget"] == budget]
    return [verdict_sentence(r) for _, r in rows.iterrows()]


def headline(verdicts: pd.DataFrame) -> str:
    """The page's first sentence: each category's verdict at the headline budget (else the
    middle budget) in the first ranking metric, each naming its category; empty without a
    verdict."""
    if verdicts.empty:
        return ""
    budgets = sorted(verdicts["budget"].unique())
    budget = HEADLINE_BUDGET if HEADLINE_BUDGET in budgets else budgets[len(budgets) // 2]
    at = verdicts[verdicts["budget"] == budget]
    at = at[at["metric"] == at["metric"].iloc[0]]
    return " ".join(verdict_sentence(r) for _, r in at.iterrows())
