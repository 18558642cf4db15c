"""Table 1, Table 2 and the paired comparisons, from the rows of `runs.csv` alone.

* `table1.csv`: per strategy and budget, the headline task and protocol (`tri`,
  `multiview`) and beside it the `sfm` task's metrics (prefixed `sfm_`: mAA, registered
  views, ...): the mean of every metric over runs with a 95% bootstrap interval
  (`<metric>_lo`, `<metric>_hi`; `bench.harness.stats`). The stock-COLMAP peers have sfm
  columns only. `table1_twoview.csv`: both tasks under the `twoview` track protocol, never
  mixed into the headline.
* `completeness_vs_oracle_pct`: a run's completeness as a percentage of the oracle's in the
  same scene, seed and budget (the oracle is the ground-truth selection under the same
  budget, `bench.evaluation.oracle`).
* `table2.csv`: per scene (and all scenes pooled) and budget, adaptive against the best
  baseline (random, texture, grid and the field's selectors response, ssc, quadtree; never
  a reference) for each headline metric, with the paired difference to that baseline.
  `paired.csv`: adaptive against every other policy that is not a reference, per scene
  and pooled, for every headline metric. `paired_sfm.csv`: every budgeted policy (and
  the oracle) against stock COLMAP held to B keypoints (`colmap-b`) in the sfm task's
  mAA and registered views, per scene and pooled.
* `table_scenes.csv`: per scene, policy and budget, the mean over seeds of the headline
  metrics and the sfm task's mAA and registered views.
* `frontend_cost.csv`: per policy, the measured front-end time of a run (detection, the
  signals the policy reads with the geometry they need, and its selection, which for
  `adaptive-loop` includes its matching rounds), in ms and relative to texture-only in the
  same units: with the rig's poses (`tri`) and with the geometry from the images (`sfm`,
  `_posefree`), and the ratio of the two (`posefree_to_posed`).

A run that reconstructed nothing has no rmse (left out of that mean; `failed_runs` counts
such runs) and zero completeness (kept in the completeness mean).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.harness.pipeline import ORACLE, REFERENCES, TASKS
from bench.harness.stats import LOWER_IS_BETTER, bootstrap_mean, paired_difference

KEY = ("scene", "seed", "policy", "budget", "task", "protocol")
DISPLAY = {
    "random": "Random budget",
    "texture": "Texture-only",
    "grid": "Uniform grid",
    "response": "Detector response (top-B)",
    "ssc": "SSC (Bailo 2018)",
    "quadtree": "Quadtree (ORB-SLAM)",
    "adaptive": "Adaptive optimized",
    "adaptive-fast": "Adaptive, cheap repeatability",
    "adaptive-loop": "Adaptive feedback loop",
    "learned": "Learned weights",
    "cross-view": "Adaptive + epipolar signal",
    "all": "All candidates (reference)",
    ORACLE: "Oracle (ground truth, reference)",
    "colmap": "COLMAP default SIFT (peer)",
    "colmap-b": "COLMAP SIFT, B largest-scale (peer)",
    "colmap-soft-b": "COLMAP SIFT soft limit B (peer)",
}
BASELINES = ("random", "texture", "grid", "response", "ssc", "quadtree")
CONTENDER = "adaptive"
PEER = "colmap-b"
"""The stock-COLMAP peer held to the same budget, which `paired_sfm.csv` compares with."""
HEADLINE = ("tri", "multiview")
"""The headline task and track protocol."""
HEADLINE_BUDGET = 256
TABLE1_METRICS = (
    "rmse",
    "acc_completeness_pct",
    "completeness_vs_oracle_pct",
    "accuracy_pct",
    "inlier_pct",
    "coverage_pct",
    "runtime_proxy",
    "wall_ms",
    "median_error",
    "match_precision_pct",
    "acc_completeness_pct_0.02",
    "acc_completeness_pct_0.05",
    "acc_completeness_pct_0.20",
    "accuracy_pct_0.02",
    "accuracy_pct_0.05",
    "accuracy_pct_0.20",
    "points",
    "reconstructable",
    "mean_track_length",
    "mean_tri_angle_deg",
    "runtime_scoring",
    "runtime_matching",
    "runtime_robust",
    "task_ms",
)
SFM_METRICS = (
    "maa",
    "keypoints_per_view",
    "registered_views",
    "median_pose_err_deg",
    "cam_center_err",
    "points",
    "accuracy_pct",
    "rmse",
    "median_error",
    "mean_track_length",
    "mean_reproj_px",
    "task_ms",
    "wall_ms",
)
"""The sfm task's columns in Table 1 (as `sfm_<name>`)."""
PAIRED_METRICS = ("acc_completeness_pct", "accuracy_pct", "rmse", "median_error", "sfm_maa")
"""The headline metrics that paired statistics compare."""
UNIT = ["scene", "seed", "policy", "budget"]


def headline_frame(df: pd.DataFrame, protocol: str = HEADLINE[1]) -> pd.DataFrame:
    """One row per (scene, seed, policy, budget) under a track protocol: the known-pose
    task's columns, and the sfm task's as `sfm_<name>` (a unit with only one of the tasks
    has NaN for the other)."""
    rows = df[df["protocol"] == protocol]
    tri = rows[rows["task"] == "tri"]
    cols = [c for c in (*SFM_METRICS, "status") if c in df]
    sfm = rows[rows["task"] == "sfm"][UNIT + cols].rename(columns={c: f"sfm_{c}" for c in cols})
    return tri.merge(sfm, on=UNIT, how="outer")


def with_oracle_share(df: pd.DataFrame) -> pd.DataFrame:
    """Add `completeness_vs_oracle_pct` (NaN where there is no oracle run or it is 0)."""
    keys = ["scene", "seed", "budget", "task", "protocol"]
    oracle = df[df["policy"] == ORACLE].set_index(keys)["acc_completeness_pct"]
    ref = np.array([oracle.get(k, math.nan) for k in df.set_index(keys).index], dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = 100.0 * df["acc_completeness_pct"].to_numpy(dtype=float) / ref
    return df.assign(completeness_vs_oracle_pct=np.where(ref > 0, share, math.nan))


def _policy_order(policy: str) -> int:
    return list(DISPLAY).index(policy) if policy in DISPLAY else len(DISPLAY)


def table1(rows: pd.DataFrame) -> pd.DataFrame:
    """Per strategy and budget: every metric's mean and 95% bootstrap interval over runs
    (`rows`: `headline_frame`, or the rows of one task and protocol)."""
    out = []
    metrics = [*TABLE1_METRICS, *(f"sfm_{m}" for m in SFM_METRICS)]
    for (policy, budget), g in rows.groupby(["policy", "budget"], sort=False):
        row = {"strategy": DISPLAY.get(policy, policy), "policy": policy, "budget": budget}
        row["runs"] = len(g)
        row["failed_runs"] = int((g["status"] == "failed").sum())
        if "sfm_status" in g:
            row["sfm_failed_runs"] = int((g["sfm_status"] == "failed").sum())
        for m in metrics:
            if m in g:
                row[m], row[f"{m}_lo"], row[f"{m}_hi"] = bootstrap_mean(g[m].astype(float))
        out.append(row)
    t = pd.DataFrame(out)
    if t.empty:
        return t
    order = t.apply(
        lambda r: (r["budget"] if r["budget"] > 0 else math.inf, _policy_order(r["policy"])), axis=1
    )
    return t.loc[order.sort_values().index].reset_index(drop=True)


def _units(df: pd.DataFrame, policy: str, budget: int, metric: str) -> pd.Series:
    g = df[(df["policy"] == policy) & (df["budget"] == budget)]
    return g.set_index(["scene", "seed"])[metric].astype(float)


def _paired(rows: pd.DataFrame, pairs: list[tuple[str, str]], metrics) -> pd.DataFrame:
    """Policy minus baseline for each (policy, baseline) of `pairs`, per scene and pooled,
    per budget and metric, over the (scene, seed) units both ran."""
    out = []
    for budget in sorted(b for b in pd.unique(rows["budget"]) if b > 0):
        for scope in [*pd.unique(rows["scene"]), "all scenes"]:
            part = rows if scope == "all scenes" else rows[rows["scene"] == scope]
            for policy, base in pairs:
                for m in (m for m in metrics if m in part):
                    a, b = _units(part, policy, budget, m), _units(part, base, budget, m)
                    strata = pd.Series(a.index.get_level_values("scene"), index=a.index)
                    res = paired_difference(a, b, strata, m)  # n = 0 when either is missing
                    out.append(
                        {
                            "scene": scope,
                            "budget": budget,
                            "policy": policy,
                            "baseline": base,
                            "metric": m,
                            **res,
                        }
                    )
    return pd.DataFrame(out)


def paired(rows: pd.DataFrame) -> pd.DataFrame:
    """Adaptive minus each baseline, per scene and pooled, per budget and headline metric
    (`rows`: `headline_frame`)."""
    baselines = [p for p in pd.unique(rows["policy"]) if p not in (CONTENDER, *REFERENCES)]
    return _paired(rows, [(CONTENDER, b) for b in baselines], PAIRED_METRICS)


def paired_sfm(rows: pd.DataFrame) -> pd.DataFrame:
    """Every budgeted policy (and the oracle) minus the peer held to the budget,
    `colmap-b`, in the sfm task's mAA and registered views, per scene and pooled, per
    budget (`rows`: `headline_frame`)."""
    if PEER not in set(rows["policy"]):
        return pd.DataFrame()
    policies = [p for p in pd.unique(rows["policy"]) if p not in REFERENCES or p == ORACLE]
    return _paired(rows, [(p, PEER) for p in policies], ("sfm_maa", "sfm_registered_views"))


def table2(rows: pd.DataFrame, pairs: pd.DataFrame) -> pd.DataFrame:
    """Per scene (and pooled) and budget: adaptive, the best baseline of each headline metric
    and the paired difference to it, plus the oracle's completeness (`rows`:
    `headline_frame`)."""
    out = []
    for budget in sorted(b for b in pd.unique(rows["budget"]) if b > 0):
        for scope in [*pd.unique(rows["scene"]), "all scenes"]:
            part = rows[rows["budget"] == budget]
            part = part if scope == "all scenes" else part[part["scene"] == scope]
            means = part.groupby("policy")[[m for m in PAIRED_METRICS if m in part]].mean()
            row = {"scene": scope, "budget": budget}
            for m in (m for m in PAIRED_METRICS if m in means):
                row[f"adaptive_{m}"] = means[m].get(CONTENDER, math.nan)
                base = means.loc[[p for p in BASELINES if p in means.index], m].dropna()
                best = (
                    (base.idxmin() if m in LOWER_IS_BETTER else base.idxmax()) if len(base) else ""
                )
                row[f"best_baseline_{m}"] = base.get(best, math.nan) if best else math.nan
                row[f"best_baseline_{m}_policy"] = best
                p = pairs[
                    (pairs["scene"] == scope)
                    & (pairs["budget"] == budget)
                    & (pairs["baseline"] == best)
                    & (pairs["metric"] == m)
                ]
                r = p.iloc[0] if len(p) else {}
                row[f"diff_{m}"] = r.get("mean_diff", math.nan)
                row[f"diff_{m}_lo"] = r.get("lo", math.nan)
                row[f"diff_{m}_hi"] = r.get("hi", math.nan)
                row[f"diff_{m}_wtl"] = f"{r['wins']}/{r['ties']}/{r['losses']}" if len(p) else ""
            row["oracle_acc_completeness_pct"] = means["acc_completeness_pct"].get(ORACLE, math.nan)
            out.append(row)
    t = pd.DataFrame(out)
    # the DESIGN.md column names of the first table 2
    return t.rename(
        columns={
            "best_baseline_acc_completeness_pct_policy": "best_baseline_acc_completeness_policy",
        }
    )


SCENE_METRICS = ("acc_completeness_pct", "accuracy_pct", "rmse", "points", "coverage_pct")


def table_scenes(rows: pd.DataFrame) -> pd.DataFrame:
    """Per scene, policy and budget: means over seeds (`rows`: `headline_frame`)."""
    cols = [m for m in (*SCENE_METRICS, "sfm_maa", "sfm_registered_views") if m in rows]
    t = rows.groupby(["scene", "policy", "budget"], sort=False)[cols].mean().reset_index()
    t.insert(3, "seeds", rows.groupby(["scene", "policy", "budget"], sort=False).size().values)
    order = t.apply(lambda r: (r["scene"], r["budget"], _policy_order(r["policy"])), axis=1)
    return t.loc[order.sort_values().index].reset_index(drop=True)


def frontend_cost(df: pd.DataFrame) -> pd.DataFrame:
    """Per policy: mean front-end ms of a run (detect + its signals + select) with the
    rig's poses (the `tri` task) and the mean ratio to texture-only over the units both
    ran; the same with the geometry from the images (the `sfm` task, `_posefree`) and the
    mean ratio of the pose-free to the posed front end over the units both ran."""
    parts = ["detect_ms", "signals_ms", "select_ms"]
    rows = df[(df["protocol"] == HEADLINE[1]) & ~df["policy"].isin([ORACLE, *REFERENCES])]
    if rows.empty or not set(parts) <= set(rows):
        return pd.DataFrame()
    unit = ["scene", "seed", "budget", "policy"]
    front = {task: rows[rows["task"] == task].set_index(unit)[parts].sum(axis=1) for task in TASKS}
    out = []
    for policy in dict.fromkeys(rows["policy"]):
        row = {"policy": policy}
        for task, suffix in (("tri", ""), ("sfm", "_posefree")):
            f = front[task]
            units = f[f.index.get_level_values("policy") == policy].droplevel("policy")
            has_texture = "texture" in set(f.index.get_level_values("policy"))
            tex = f.xs("texture", level="policy") if has_texture else None
            row[f"frontend_ms{suffix}"] = units.mean() if len(units) else math.nan
            row[f"ratio_to_texture{suffix}"] = (
                (units / tex.reindex(units.index)).mean() if tex is not None else math.nan
            )
        posed = front["tri"][front["tri"].index.get_level_values("policy") == policy]
        free = front["sfm"][front["sfm"].index.get_level_values("policy") == policy]
        row["posefree_to_posed"] = (free / posed.reindex(free.index)).mean()
        out.append(row)
    t = pd.DataFrame(out)
    return t.iloc[t["policy"].map(_policy_order).argsort(kind="stable")].reset_index(drop=True)
