"""Table 1, Table 2 and the paired comparisons, from the rows of `runs.csv` alone.

* `table1.csv`: per strategy and budget, the headline task and protocol (`tri`,
  `multiview`) and beside it the `sfm` task's metrics (prefixed `sfm_`: mAA, registered
  views, ...): the mean of every metric over runs with a 95% bootstrap interval
  (`<metric>_lo`, `<metric>_hi`; `bench.report.stats`). The stock-COLMAP peers have sfm
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

from bench.report.stats import LOWER_IS_BETTER, bootstrap_mean, paired_difference
from bench.vocabulary import HEADLINE, HEADLINE_POLICY, ORACLE, PAIRED_PEER, UNIT_KEY, Vocabulary

PAIRED_METRICS = ("acc_completeness_pct", "accuracy_pct", "rmse", "median_error", "sfm_maa")
"""The headline metrics that paired statistics compare."""
UNIT = list(UNIT_KEY)


def headline_frame(
    df: pd.DataFrame, vocab: Vocabulary, protocol: str = HEADLINE[1]
) -> pd.DataFrame:
    """One row per (scene, seed, policy, budget) under a track protocol: the headline
    task's columns, and every other task's as `<task>_<name>` (a unit without one of the
    tasks has NaN for it)."""
    rows = df[df["protocol"] == protocol]
    frame = rows[rows["task"] == HEADLINE[0]]
    for task in (t for t in vocab.tasks if t != HEADLINE[0]):
        cols = [c for c in (*vocab.tasks[task].columns, "status") if c in df]
        part = rows[rows["task"] == task][UNIT + cols]
        frame = frame.merge(
            part.rename(columns={c: f"{task}_{c}" for c in cols}), on=UNIT, how="outer"
        )
    return frame


def with_oracle_share(df: pd.DataFrame) -> pd.DataFrame:
    """Add `completeness_vs_oracle_pct` (NaN where there is no oracle run or it is 0)."""
    keys = ["scene", "seed", "budget", "task", "protocol"]
    oracle = df[df["policy"] == ORACLE].set_index(keys)["acc_completeness_pct"]
    ref = np.array([oracle.get(k, math.nan) for k in df.set_index(keys).index], dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = 100.0 * df["acc_completeness_pct"].to_numpy(dtype=float) / ref
    return df.assign(completeness_vs_oracle_pct=np.where(ref > 0, share, math.nan))


def table1(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per strategy and budget: every metric's mean and 95% bootstrap interval over runs
    (`rows`: `headline_frame`, or the rows of one task and protocol)."""
    out = []
    others = [t for t in vocab.tasks if t != HEADLINE[0]]
    metrics = [*vocab.tasks[HEADLINE[0]].columns]
    metrics += [f"{t}_{m}" for t in others for m in vocab.tasks[t].columns]
    for (policy, budget), g in rows.groupby(["policy", "budget"], sort=False):
        row = {"strategy": vocab.label(policy), "policy": policy, "budget": budget}
        row["runs"] = len(g)
        row["failed_runs"] = int((g["status"] == "failed").sum())
        for t in (t for t in others if f"{t}_status" in g):
            row[f"{t}_failed_runs"] = int((g[f"{t}_status"] == "failed").sum())
        for m in metrics:
            if m in g:
                row[m], row[f"{m}_lo"], row[f"{m}_hi"] = bootstrap_mean(g[m].astype(float))
        out.append(row)
    t = pd.DataFrame(out)
    if t.empty:
        return t
    order = t.apply(
        lambda r: (r["budget"] if r["budget"] > 0 else math.inf, vocab.order(r["policy"])), axis=1
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


def paired(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """The headline policy (adaptive) minus every other baseline or contender, per scene
    and pooled, per budget and headline metric (`rows`: `headline_frame`)."""
    ranked = set(vocab.with_role("baseline", "contender")) - {HEADLINE_POLICY}
    others = [p for p in pd.unique(rows["policy"]) if p in ranked]
    return _paired(rows, [(HEADLINE_POLICY, b) for b in others], PAIRED_METRICS)


def paired_sfm(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Every budgeted policy (and the oracle) minus the peer held to the budget,
    `colmap-b`, in the sfm task's mAA and registered views, per scene and pooled, per
    budget (`rows`: `headline_frame`)."""
    if PAIRED_PEER not in set(rows["policy"]):
        return pd.DataFrame()
    ranked = {*vocab.with_role("baseline", "contender"), ORACLE}
    policies = [p for p in pd.unique(rows["policy"]) if p in ranked]
    return _paired(rows, [(p, PAIRED_PEER) for p in policies], ("sfm_maa", "sfm_registered_views"))


def table2(rows: pd.DataFrame, pairs: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
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
                row[f"adaptive_{m}"] = means[m].get(HEADLINE_POLICY, math.nan)
                baselines = vocab.with_role("baseline")
                base = means.loc[[p for p in baselines if p in means.index], m].dropna()
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
    # the column name Table 2 has had since its first version
    return t.rename(
        columns={
            "best_baseline_acc_completeness_pct_policy": "best_baseline_acc_completeness_policy",
        }
    )


SCENE_METRICS = ("acc_completeness_pct", "accuracy_pct", "rmse", "points", "coverage_pct")


def table_scenes(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per scene, policy and budget: means over seeds (`rows`: `headline_frame`)."""
    cols = [m for m in (*SCENE_METRICS, "sfm_maa", "sfm_registered_views") if m in rows]
    t = rows.groupby(["scene", "policy", "budget"], sort=False)[cols].mean().reset_index()
    t.insert(3, "seeds", rows.groupby(["scene", "policy", "budget"], sort=False).size().values)
    order = t.apply(lambda r: (r["scene"], r["budget"], vocab.order(r["policy"])), axis=1)
    return t.loc[order.sort_values().index].reset_index(drop=True)


def frontend_cost(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per policy: mean front-end ms of a run (detect + its signals + select) with the
    rig's poses (the `tri` task) and the mean ratio to texture-only over the units both
    ran; the same with the geometry from the images (the `sfm` task, `_posefree`) and the
    mean ratio of the pose-free to the posed front end over the units both ran."""
    parts = ["detect_ms", "signals_ms", "select_ms"]
    ranked = vocab.with_role("baseline", "contender")
    rows = df[(df["protocol"] == HEADLINE[1]) & df["policy"].isin(ranked)]
    if rows.empty or not set(parts) <= set(rows):
        return pd.DataFrame()
    unit = ["scene", "seed", "budget", "policy"]
    front = {
        task: rows[rows["task"] == task].set_index(unit)[parts].sum(axis=1) for task in vocab.tasks
    }
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
    return t.iloc[t["policy"].map(vocab.order).argsort(kind="stable")].reset_index(drop=True)
