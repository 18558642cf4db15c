"""Statistics of the tables: bootstrap percentile intervals and paired differences.

* A metric's aggregate is the mean over runs with a 95% bootstrap percentile interval
  (10,000 resamples of the runs, seeded): the interval is made of means of the data, so it
  stays within the metric's range (no completeness below 0% or above 100%). With fewer
  than two runs there is no interval (NaN), and it is shown as missing.
* A paired comparison of policy A with policy B on a metric takes the difference A - B of
  each (scene, seed) both ran; its mean gets a 95% bootstrap interval that resamples the
  seeds within each scene (so a pooled interval keeps the mix of scenes fixed), and the
  pairs are counted as wins, ties (equal values) and losses for A, by the metric's
  direction.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

RESAMPLES = 10_000
LOWER_IS_BETTER = {
    "rmse",
    "median_error",
    "runtime_proxy",
    "wall_ms",
    "sfm_rmse",
    "sfm_median_error",
    "sfm_median_pose_err_deg",
    "sfm_cam_center_err",
}


def bootstrap_mean(x, seed: int = 0) -> tuple[float, float, float]:
    """(mean, lower, upper) of the finite values, with a 95% percentile interval."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    if len(x) == 1:
        return float(x[0]), math.nan, math.nan
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), (RESAMPLES, len(x)))].mean(1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(x.mean()), float(lo), float(hi)


def paired_difference(
    a: pd.Series, b: pd.Series, strata: pd.Series, metric: str, seed: int = 0
) -> dict:
    """A - B over the units (index) both have, with a bootstrap interval that resamples
    units within each stratum, and wins / ties / losses of A."""
    d = (a - b).dropna()
    if d.empty:
        return {
            "n": 0,
            "mean_diff": math.nan,
            "lo": math.nan,
            "hi": math.nan,
            "wins": 0,
            "ties": 0,
            "losses": 0,
        }
    better = -d if metric in LOWER_IS_BETTER else d
    groups = [d[strata.loc[d.index] == s].to_numpy() for s in pd.unique(strata.loc[d.index])]
    rng = np.random.default_rng(seed)
    total = sum(len(g) for g in groups)
    sums = sum(g[rng.integers(0, len(g), (RESAMPLES, len(g)))].sum(1) for g in groups)
    lo, hi = np.percentile(sums / total, [2.5, 97.5]) if len(d) > 1 else (math.nan, math.nan)
    return {
        "n": len(d),
        "mean_diff": float(d.mean()),
        "lo": float(lo),
        "hi": float(hi),
        "wins": int((better > 0).sum()),
        "ties": int((better == 0).sum()),
        "losses": int((better < 0).sum()),
    }
