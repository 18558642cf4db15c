"""Statistics of the tables: means and paired differences with 95% intervals.

Units are (scene, seed) runs and the strata are scenes. A mean over runs (Table 1) or a
paired difference A - B over the units both ran (`paired.csv`) is the plain mean of the
units, and its 95% interval is a stratified t-interval: the variance of the mean is
sum_s (n_s / N)^2 s_s^2 / n_s over the scenes s (s_s the spread of the n_s seeds of
scene s), with Welch-Satterthwaite degrees of freedom. It is an interval for the mean over
these scenes (the mix of scenes is fixed; a new scene could differ more). A scene with
fewer than two seeds, or with every value equal within each scene, gives no spread to
measure: there is then no interval (NaN), and `note` says why.

Its coverage at this grid's shape (3 or 4 scenes x 5 seeds), measured by
`benchmarks/interval_coverage.py` (2,000 simulated grids per noise model), pooled over
scenes: 95.0-97.2% with normal, unequal-per-scene or heavy-tailed noise and with an mAA
in [0, 1] (the percentile bootstrap it replaces: 86.9-90.2%), 92-93% with skewed noise
(86-87%), 88% with very skewed noise (80-82%) and 92% for an mAA mostly at 0 (78-81%).
Per scene (5 seeds): 95-97% with symmetric noise (the bootstrap 83-88%), 87-89% with
skewed noise or an mAA in [0, 1] (76-80%), 81-84% with very skewed noise or an mAA mostly
at 0 (50-73%): read a single scene's interval of mAA as indicative.

Paired units are also counted as wins, ties (equal values) and losses for A, by the
metric's direction (declared by its task, `bench.vocabulary.Task.lower_better`).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.special import stdtrit

LEVEL = 0.95


def stratified_interval(x, strata=None) -> tuple[float, float, float, str]:
    """(mean, lower, upper, note) of the finite values of `x`, with the stratified
    t-interval of the module docstring (`strata`: each value's scene; None: one stratum).
    Without an interval (a stratum with one value, or no value) the bounds are NaN and
    `note` says why; otherwise it is empty."""
    x = np.asarray(x, float)
    strata = np.zeros(len(x), int) if strata is None else np.asarray(strata)
    keep = np.isfinite(x)
    x, strata = x[keep], strata[keep]
    if len(x) == 0:
        return math.nan, math.nan, math.nan, "n/a (no run)"
    mean = float(x.mean())
    groups = [x[strata == s] for s in pd.unique(strata)]
    smallest = min(len(g) for g in groups)
    if smallest < 2:
        return mean, math.nan, math.nan, f"n/a ({smallest} seed{'s' * (smallest != 1)})"
    parts = np.array([(len(g) / len(x)) ** 2 * g.var(ddof=1) / len(g) for g in groups])
    var = parts.sum()
    if var == 0:  # every value equal within its scene: no spread to measure
        return mean, math.nan, math.nan, "n/a (no spread)"
    dof = var**2 / sum(p**2 / (len(g) - 1) for p, g in zip(parts, groups))
    half = float(stdtrit(dof, 0.5 + LEVEL / 2)) * math.sqrt(var)
    return mean, mean - half, mean + half, ""


def paired_difference(d, strata, lower_better: bool) -> dict:
    """Paired differences A - B, one a unit (NaN where A or B has no value: the unit is left
    out), and each unit's scene (`strata`): their mean with the stratified interval
    (`stratified_interval`), and wins / ties / losses of A (`lower_better`: the metric's
    direction, `Task.lower_better`)."""
    d, strata = np.asarray(d, float), np.asarray(strata)
    keep = ~np.isnan(d)
    d, strata = d[keep], strata[keep]
    better = -d if lower_better else d
    mean, lo, hi, note = stratified_interval(d, strata)
    return {
        "n": len(d),
        "mean_diff": mean,
        "lo": lo,
        "hi": hi,
        "note": note,
        "wins": int((better > 0).sum()),
        "ties": int((better == 0).sum()),
        "losses": int((better < 0).sum()),
    }
