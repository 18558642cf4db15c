"""`table_pools.csv`: which detector and which selection at a budget, from a grid run on
several candidate pools (`bench run --pools`; rows carry their `pool` and `matcher`).

Per budget, ranking metric (the first headline metric of each task the peers run, as
`verdicts.csv`) and pool (a detector with its matcher): the pool's own top-B peer and the
best selection of each category (`sees`: its own image, other views) on that pool, each
with its mean over the cells that count (`bench.report.tables.solvable`) and its paired
difference, over the (scene, seed) units both have, with its 95% interval
(`bench.report.stats.paired_difference`), from each of two references (`vs`, a row
each): `BASELINE`, stock COLMAP's SIFT held to B (what the field runs at a budget), and
the pool's own top-B peer (`aliked-b`), which a selection on a pool must beat to be
worth its cost. The stock-COLMAP peers extract their own SIFT keypoints: their pool is
`colmap`. `recommendation` says, per budget, metric and category, which (pool, method)
leads, and its differences from both.
"""

from __future__ import annotations

import math

import pandas as pd

from bench.report.categories import (
    CATEGORIES,
    POLICY_ROLES,
    _best,
    _signed,
    _three,
    _verdict,
    peer_metrics,
)
from bench.report.stats import paired_difference
from bench.report.tables import solvable
from bench.vocabulary import Vocabulary

BASELINE = "colmap-b"
OWN_EXTRACTION = "colmap"
"""The pool named for the rows of a peer that extracts its own keypoints (no `pool`)."""


def pools_of(frame: pd.DataFrame) -> pd.Series:
    """Each row's pool and matcher as one name (`aliked/lightglue`; `colmap` for a peer
    that extracts its own)."""
    pool = frame["pool"].fillna("").astype(str)
    matcher = frame["matcher"].fillna("").astype(str)
    return (pool + "/" + matcher).where(pool != "", OWN_EXTRACTION)


def table_pools(frame: pd.DataFrame, vocab: Vocabulary, rows: pd.DataFrame) -> pd.DataFrame:
    """`table_pools.csv` (module docstring; `frame`: the `headline_frame` of `rows`, the
    runs); empty unless the rows ran on two pools or more."""
    if "pool" not in rows or rows["pool"].fillna("").nunique() < 2:
        return pd.DataFrame()
    lower = vocab.lower_better()
    pool_of = dict(zip(rows["method"], pools_of(rows)))
    out = []
    for metric in (m for m in peer_metrics(vocab) if m in frame):
        counted = solvable(frame, metric, vocab)
        counted = counted.assign(pool_name=counted["method"].map(pool_of))
        for budget in sorted(b for b in pd.unique(counted["budget"]) if b > 0):
            at = counted[counted["budget"] == budget]
            wide = at.pivot_table(index=["scene", "seed"], columns="method", values=metric)
            for pool, on in at.groupby("pool_name", sort=True):
                leaders = list(_leaders(vocab, set(on["method"]), wide, metric in lower))
                own = next((m for role, _, m in leaders if role == "peer"), "")
                for role, sees, method in leaders:
                    row = {"budget": budget, "metric": metric, "pool": pool, "role": role}
                    row |= {"sees": sees, "method": method, "mean": wide[method].mean()}
                    row |= {"runs": int(wide[method].count())}
                    for vs in dict.fromkeys((BASELINE, own)):
                        if vs and vs != method:
                            out.append(row | _against(wide, method, vs, metric in lower))
                    if method == BASELINE:
                        out.append(row | {"vs": ""})
    return pd.DataFrame(out)


def _leaders(vocab: Vocabulary, methods: set, wide: pd.DataFrame, lower: bool):
    """(role, sees, method): the pool's best peer held to B, and its best selection of
    each category."""
    budgeted = [m for m in methods if m in vocab.methods and not vocab.methods[m].whole_pool]
    peers = [m for m in budgeted if vocab.methods[m].role == "peer" and "@" not in m]
    best = _best(wide, peers, lower)
    if best:
        yield "peer", vocab.sees(best), best
    for sees in CATEGORIES:
        chosen = [m for m in budgeted if vocab.methods[m].role in POLICY_ROLES]
        best = _best(wide, [m for m in chosen if vocab.sees(m) == sees], lower)
        if best:
            yield "selection", sees, best


def _against(wide: pd.DataFrame, method: str, vs: str, lower: bool) -> dict:
    """`method` minus `vs` over the units both have (none where `vs` did not run)."""
    if vs not in wide:
        return {"vs": vs, "n": 0, "mean_diff": math.nan, "lo": math.nan, "hi": math.nan}
    both = wide[[method, vs]].dropna()
    res = paired_difference(both[method] - both[vs], both.index.get_level_values(0), lower)
    return {"vs": vs} | res | {"verdict": _verdict(res, lower)}


def _diff(r) -> str:
    """`r`'s paired difference as a sentence's clause."""
    if not r.get("n", 0) or not isinstance(r.get("verdict"), str):
        return f"against `{r['vs']}`: no paired cell"
    return (
        f"against `{r['vs']}`: {_signed(r['mean_diff'])} [{_signed(r['lo'])}, "
        f"{_signed(r['hi'])}] over {int(r['n'])} runs, {r['verdict']}"
    )


def recommendation(table: pd.DataFrame, vocab: Vocabulary) -> list[str]:
    """A sentence per budget, metric and category (`sees`): its leading (pool, method) of
    `table_pools.csv` across pools, its mean, and its differences from `BASELINE` and from
    its pool's own top-B."""
    if table.empty:
        return []
    lower = vocab.lower_better()
    out = []
    for (budget, metric, sees), at in table.groupby(["budget", "metric", "sees"], sort=True):
        best = at.sort_values("mean", ascending=metric in lower).iloc[0]
        against = at[(at["method"] == best["method"]) & (at["vs"].fillna("") != "")]
        said = "; ".join(_diff(r) for _, r in against.iterrows())
        out.append(
            f"At B = {budget} in {metric}, of the `{sees}` selections `{best['method']}` on "
            f"the {best['pool']} pool leads ({_three(best['mean'])})"
            + (f"; {said}" if said else "")
            + "."
        )
    return out
