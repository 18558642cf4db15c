"""How much a ranking can be trusted: split-half reliability, the ceiling of a transfer
figure, the real-to-real baseline, sign agreement and tiers (docs/protocol.md, "Verdicts
and their power").

A ranking is the methods' means at one budget and metric over a set of units (renders:
(scene, seed) cells; a photo set: its bags), given as a frame of units x methods.

* `split_half`: the units split into two halves (every distinct split where there are at
  most `SPLITS`, else `SPLITS` random ones, seed 0); r is the mean over splits of Kendall's
  tau-b between the halves' means; the reliability of the whole is Spearman-Brown's
  2r / (1 + r) (`spearman_brown`).
* `lengthening`: how many times more units a ranking needs to reach a reliability (the
  Spearman-Brown prophecy).
* `ceiling`: sqrt(rel_1 x rel_2), the largest correlation two rankings of these
  reliabilities can reach (Spearman's correction for attenuation); NaN unless both are
  positive.
* `real_to_real`: per set, Kendall's tau-b of the other sets' mean rank against this set's
  means (leave one out).
* `sign_agreement`: of the methods whose difference from the reference has a sign on both
  sides (zero: no sign), how many have the same sign.
* `tiers`: two-sided Wilcoxon signed-rank tests on the paired values of every pair of
  methods, Holm-corrected (`holm`); tier 1 is the best method by mean and every method not
  significantly different from it, the next tier starts at the best method left, and so on.
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy.stats import kendalltau, permutation_test, rankdata, wilcoxon

SPLITS = 200
"""The half-splits a reliability averages over (all of them where there are fewer)."""
ALPHA = 0.05
"""The family-wise error rate of the tiers' tests (Holm)."""


def tau(x, y) -> float:
    """Kendall's tau-b (NaN where either side is constant)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 2 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan
    return float(kendalltau(x, y).statistic)


def spearman_brown(r: float) -> float:
    """The reliability of a whole from the correlation r of its two halves: 2r / (1 + r)."""
    return 2 * r / (1 + r) if r > -1 else math.nan


def lengthening(rel: float, target: float) -> float:
    """How many times more units a ranking of reliability `rel` needs to reach `target`
    (the Spearman-Brown prophecy solved for its factor: target (1 - rel) / (rel (1 -
    target))); NaN unless 0 < rel and target < 1."""
    if not 0 < rel or not target < 1 or math.isnan(rel):
        return math.nan
    return target * (1 - rel) / (rel * (1 - target))


def ceiling(rel_a: float, rel_b: float) -> float:
    """sqrt(rel_a x rel_b), NaN unless both are positive."""
    return math.sqrt(rel_a * rel_b) if rel_a > 0 and rel_b > 0 else math.nan


def half_splits(n: int, splits: int = SPLITS, seed: int = 0) -> list[np.ndarray]:
    """Masks of the first half (n // 2 units) of splits of n units: every distinct split
    (a split and its mirror counted once) where there are at most `splits`, else `splits`
    random ones."""
    k = n // 2
    total = math.comb(n, k) // (2 if 2 * k == n else 1)
    if total <= splits:
        firsts = combinations(range(n), k)
        chosen = [c for c in firsts if 2 * k != n or 0 in c]
    else:
        rng = np.random.default_rng(seed)
        chosen = [rng.permutation(n)[:k] for _ in range(splits)]
    masks = []
    for c in chosen:
        m = np.zeros(n, bool)
        m[list(c)] = True
        masks.append(m)
    return masks


def split_half(values: pd.DataFrame) -> tuple[float, float]:
    """(r, reliability) of the ranking of `values` (units x methods; module docstring);
    NaN with fewer than two units or methods, or where no split ranks them."""
    values = values.dropna()
    if len(values) < 2 or values.shape[1] < 2:
        return math.nan, math.nan
    x = values.to_numpy(float)
    taus = [tau(x[m].mean(0), x[~m].mean(0)) for m in half_splits(len(x))]
    taus = [t for t in taus if not math.isnan(t)]
    if not taus:
        return math.nan, math.nan
    r = float(np.mean(taus))
    return r, spearman_brown(r)


def real_to_real(means: pd.DataFrame, lower_better: bool) -> pd.Series:
    """Per set (the rows of `means`, sets x methods), tau-b of the other sets' mean rank
    against its means; NaN with fewer than two sets."""
    sign = 1 if lower_better else -1
    ranks = (sign * means).rank(axis=1)
    out = {}
    for d in means.index:
        others = ranks.drop(index=d)
        out[d] = tau(others.mean(), sign * means.loc[d]) if len(others) else math.nan
    return pd.Series(out, dtype=float)


def sign_agreement(a: pd.Series, b: pd.Series) -> tuple[int, int]:
    """(agree, decided): of the methods with a nonzero difference on both sides, how many
    have the same sign."""
    sa, sb = np.sign(a), np.sign(b.reindex(a.index))
    decided = (sa != 0) & (sb != 0) & sa.notna() & sb.notna()
    return int((sa[decided] == sb[decided]).sum()), int(decided.sum())


def min_units(methods: int, alpha: float = ALPHA) -> int:
    """The fewest units from which `tiers` can tell two of `methods` apart: Holm's
    correction multiplies the smallest p by the pairs, and the smallest two-sided exact
    Wilcoxon p over n units is 2 / 2^n."""
    pairs, n = methods * (methods - 1) // 2, 1
    while pairs * 2.0 ** (1 - n) >= alpha:
        n += 1
    return n


def holm(p) -> np.ndarray:
    """Holm's step-down adjusted p-values (in the order given)."""
    p = np.asarray(p, float)
    order = np.argsort(p, kind="stable")
    m = len(p)
    adjusted = np.maximum.accumulate((m - np.arange(m)) * p[order]).clip(max=1)
    out = np.empty(m)
    out[order] = adjusted
    return out


PERMUTED = 13
"""The most pairs for which `scipy.stats.wilcoxon` tests zero or tied differences by
permutation (`method="auto"`)."""


def paired_p(x: np.ndarray, y: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired samples (1 where they never differ):
    `scipy.stats.wilcoxon`'s. Where it takes the exact permutation test (13 pairs or fewer,
    with zero or tied differences) its statistic is vectorised here, over all 2^n sign
    flips at once: the same null distribution and p-value (scipy calls the statistic once
    per flip; 450 random cases took 199 s through scipy's path, 5.7 s here)."""
    d = x - y
    if not np.any(d):
        return 1.0
    a = np.abs(d[d != 0])
    if len(d) <= PERMUTED and (len(a) < len(d) or len(np.unique(a)) < len(a)):
        test = permutation_test(
            (d,), _positive_ranks, permutation_type="samples", vectorized=True, axis=-1
        )
        return float(test.pvalue)
    return float(wilcoxon(x, y).pvalue)


def _positive_ranks(d: np.ndarray, axis: int = -1) -> np.ndarray:
    """Wilcoxon's statistic: the sum of the ranks of |d| that belong to positive d, zeros
    dropped (ranked last, where they add nothing), ties given their mean rank."""
    d = np.moveaxis(d, axis, -1)
    a = np.abs(d)
    return np.sum((d > 0) * rankdata(np.where(a == 0, np.inf, a), axis=-1), axis=-1)


def tiers(values: pd.DataFrame, lower_better: bool, alpha: float = ALPHA) -> pd.Series:
    """The tier of each method (1: the best's; module docstring) from `values` (units x
    methods, the units every method has)."""
    values = values.dropna()
    means = values.mean()
    order = list(means.sort_values(ascending=lower_better, kind="stable").index)
    pairs = list(combinations(order, 2))
    p = [paired_p(values[a].to_numpy(float), values[b].to_numpy(float)) for a, b in pairs]
    apart = {frozenset(pr) for pr, q in zip(pairs, holm(p) if p else []) if q < alpha}
    tier, left, out = 0, order, {}
    while left:
        tier += 1
        head = left[0]
        members = [m for m in left if m == head or frozenset((head, m)) not in apart]
        out |= dict.fromkeys(members, tier)
        left = [m for m in left if m not in members]
    return pd.Series(out).reindex(means.index)
