"""Table 1, Table 2 and the paired comparisons, from the rows of `runs.csv` alone.

* `table1.csv`: per strategy and budget, what its selection sees (`sees`: `image`, its
  own view's, or `views`, other views through a first pass; `bench.vocabulary.SEES`), the
  headline task and protocol (`tri`,
  `multiview`) and beside it every other task's metrics (prefixed with its name: `sfm_maa`,
  `pairs_auc_10`, ...): the mean of every metric over runs with a 95% interval
  (`<metric>_lo`, `<metric>_hi`; a stratified t-interval over scenes, `bench.report.stats`;
  `note` says why a row has none, e.g. `n/a (1 seed)`). The stock-COLMAP peers have sfm
  and pairs columns only. `table1_twoview.csv`: every task under the `twoview` track
  protocol, never mixed into the headline (where rows ran under it). A task without tracks
  (pairs, protocol `none`) has one row per unit, read under each protocol.
* `completeness_vs_oracle_pct`: a run's completeness as a percentage of the oracle's in the
  same scene, seed and budget (the oracle is the ground-truth selection under the same
  budget, `bench.evaluation.oracle`).
* `table2.csv`: per scene (and all scenes pooled) and budget, adaptive against the best
  baseline (random, texture, grid and the field's selectors response, ssc, quadtree; never
  a reference) for each headline metric, with the paired difference to that baseline;
  each mean is over its method's own runs and the difference over the runs both have,
  and `<adaptive>_<m>_n`, `best_baseline_<m>_n` and `diff_<m>_n` count them.
  `paired.csv`: adaptive against every other policy that is not a reference, per scene
  and pooled, for every headline metric. `paired_sfm.csv`: in the sfm task's mAA and
  registered views, per scene and pooled, every budgeted policy against each peer held to
  B keypoints that sees what it sees (`sees`: `colmap-b`, `aliked-b` and `disk-b` for
  `image`, `colmap-tracks-b` for `views`; the oracle against each), and every contender
  (and the oracle) against every baseline. Table 1's tiers are per category of `sees`
  (`with_tiers`); `verdicts.csv` judges each category against its peer
  (`bench.report.categories`).
* A (scene, seed) cell that stock COLMAP with all its features (`colmap`) does not map
  (it registers fewer than all views, or with pose mAA below 0.5; `reference_maps` is 0
  in `runs.csv`) measures
  nothing in the sfm task: its units are left out of every sfm mean and paired sfm
  difference, and `sfm_excluded_runs` (Table 1) and `sfm_excluded_seeds`
  (`table_scenes.csv`) count them. The rule holds for all cells or none (`sfm_rule`,
  Table 1's `sfm_exclusion`): it is not applied where `colmap` did not run in every cell
  of the sfm task, nor on datasets, whose poses are the truth.
* `table_scenes.csv`: per scene, policy and budget, the mean over seeds of the headline
  metrics and the sfm task's mAA and registered views.
* `frontend_cost.csv`: per policy, the measured front-end time of a run (detection, the
  signals the policy reads with the geometry they need, and its selection, which for
  `adaptive-loop` includes its matching rounds), in ms and relative to texture-only in the
  same units: with the rig's poses (`tri`) and with the geometry from the images (`sfm`,
  `_posefree`), and the ratio of the two (`posefree_to_posed`).

A run that reconstructed nothing has no rmse (left out of that mean; `failed_runs` counts
such runs) and zero completeness (kept in the completeness mean). A run that could not be
computed (its method raised or broke its contract, its worker died: `error_runs`) scores
each metric's failure value (mAA 0, AUC 0, completeness 0) in every mean, paired
difference and ranking; a metric without one (rmse) has no mean for that method and
budget (`note`: incomplete), so it is never ranked (`counted`). `note` gives, per reason
an interval is missing, the metrics it applies to.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.failures import ERROR, exclusion_rule
from bench.report.power import tiers
from bench.report.stats import paired_difference, stratified_interval
from bench.vocabulary import (
    CATEGORY_PEERS,
    EQUAL_COUNT,
    GROUND_TRUTH,
    HEADLINE,
    HEADLINE_POLICY,
    NO_PROTOCOL,
    REFERENCE_MAPS,
    UNIT_KEY,
    Vocabulary,
    equal_parts,
)

UNIT = list(UNIT_KEY)


def rule_column(vocab: Vocabulary, task: str) -> str:
    """The `headline_frame` column (and Table 1's) saying whether the exclusion rule is
    applied to a task with it (`exclusion_rule`): `sfm_exclusion` for the sfm task."""
    return vocab.column(task, "exclusion")


def counted(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """The rows as every mean counts them, with `error` marking the rows that could not be
    computed (their failure starts with `ERROR`: a method raised, broke its contract or
    lost its worker): such a row scores each metric of its task that has a failure value
    (`Metric.failure`: mAA 0, AUC 0, completeness 0), and a metric without one (rmse) is
    blanked in every row of the method, budget, task and protocol where a row could not
    be computed: an incomplete mean is never shown or ranked."""
    failure = df["failure"] if "failure" in df else pd.Series("", index=df.index)
    error = failure.fillna("").str.startswith(ERROR)
    df = df.assign(error=error)
    if not error.any():
        return df
    keys = ["method", "budget", "task", "protocol"]
    hit = error.groupby([df[k] for k in keys]).transform("any")
    for task, t in vocab.tasks.items():
        mine = df["task"] == task
        for name in (m for m in t.metrics if m in df):
            value = vocab.metrics[name].failure
            if value is None:
                df.loc[mine & hit, name] = math.nan
            else:
                df.loc[mine & error, name] = value
    return df


def headline_frame(
    df: pd.DataFrame, vocab: Vocabulary, protocol: str = HEADLINE[1], dataset: bool = False
) -> pd.DataFrame:
    """One row per (scene, seed, method, budget) under a track protocol, as the means
    count them (`counted`): the headline task's columns, and every other task's as
    `<task>_<name>` (a unit without one of the tasks has NaN for it); with a task with the
    exclusion rule (`Task.exclusion_reference`), its `rule_column` and, where the rule is
    applied, `REFERENCE_MAPS` (`dataset`: the rows are of datasets)."""
    under = df["protocol"].isin((protocol, NO_PROTOCOL))  # a task without tracks: under each
    rows = counted(df[under].copy(), vocab)  # .copy(): its blocks joined
    frame = rows[rows["task"] == HEADLINE[0]].drop(columns=REFERENCE_MAPS, errors="ignore")
    for task in (t for t in vocab.tasks if t != HEADLINE[0]):
        cols = [c for c in (*vocab.tasks[task].metrics, "status", "error") if c in rows]
        part = rows[rows["task"] == task][UNIT + cols]
        frame = frame.merge(
            part.rename(columns={c: f"{task}_{c}" for c in cols}), on=UNIT, how="outer"
        )
    ruled = [t for t in vocab.exclusion_tasks if (df["task"] == t).any()]
    rule = exclusion_rule(df, vocab, dataset) if ruled else None
    added = {rule_column(vocab, task): rule for task in ruled}
    if rule == "applied":  # a property of the (scene, seed): on every unit of it
        cells = df.dropna(subset=[REFERENCE_MAPS]).groupby(["scene", "seed"])[REFERENCE_MAPS]
        maps = cells.first()
        added[REFERENCE_MAPS] = [maps.get(k) for k in zip(frame["scene"], frame["seed"])]
    # one block per dtype: each outer merge leaves a block per column, and a column added
    # to 100 of them is pandas' PerformanceWarning
    return frame.copy().assign(**added)


def solvable(rows: pd.DataFrame, metric: str, vocab: Vocabulary) -> pd.DataFrame:
    """The rows that count for `metric`, with their unit (`UNIT`) and `metric` alone: for a
    metric of a task with the exclusion rule (sfm), those of (scene, seed) cells that stock
    COLMAP with all features maps (a cell it does not map measures nothing)."""
    part = rows[[*UNIT, metric]]
    if REFERENCE_MAPS not in rows or not vocab.excluded(metric):
        return part
    return part[rows[REFERENCE_MAPS].ne(0)]


def with_shares(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Add the report's own metrics (`Metric.share_of`, `completeness_vs_oracle_pct`): a
    run's metric as a percentage of the ground-truth method's in the same cell (NaN where
    that did not run or is 0, or the rows do not measure the metric)."""
    keys = ["scene", "seed", "budget", "task", "protocol"]
    truth = df["method"].isin(vocab.with_kind(GROUND_TRUTH))
    shares = {}
    for share, of in vocab.shares().items():
        if of not in df:
            shares[share] = math.nan
            continue
        ref = df[truth].set_index(keys)[of]
        ref = np.array([ref.get(k, math.nan) for k in df.set_index(keys).index], dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = 100.0 * df[of].to_numpy(dtype=float) / ref
        shares[share] = np.where(ref > 0, value, math.nan)
    return df.copy().assign(**shares)  # .copy(): its blocks joined before the columns added


def within(lo: float, hi: float, bounds) -> tuple[float, float]:
    """An interval clipped to the metric's declared range (the mean lies in it, so the
    clipped interval covers it whenever the whole one does)."""
    if bounds is None or math.isnan(lo):
        return lo, hi
    return max(lo, bounds[0]), hi if bounds[1] is None else min(hi, bounds[1])


def table1(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per strategy and budget: every metric's mean and 95% interval over runs, the scenes
    as strata (`rows`: `headline_frame`, or the rows of one task and protocol)."""
    out = []
    others = [t for t in vocab.tasks if t != HEADLINE[0]]
    metrics = [c for t in (HEADLINE[0], *others) for c in vocab.columns(t)]
    summaries = {}  # (metric, method, budget): (mean, lo, hi, note, whether any value)
    for m in (m for m in metrics if m in rows):
        for (policy, budget), x in solvable(rows, m, vocab).groupby(["method", "budget"]):
            values = x[m].astype(float)
            summaries[m, policy, budget] = (
                *stratified_interval(values, x["scene"]),
                values.notna().any(),
            )
    none = (math.nan, math.nan, math.nan, "", False)  # no row counts for the metric
    for (policy, budget), g in rows.groupby(["method", "budget"], sort=False):
        row = {"strategy": vocab.label(policy), "method": policy, "sees": vocab.sees(policy)}
        row["budget"] = budget
        row["runs"] = len(g)
        errors = {}  # per task: the runs that could not be computed (`counted`)
        for t in (t for t in (HEADLINE[0], *others) if vocab.column(t, "status") in g):
            failed = g[vocab.column(t, "status")] == "failed"
            error = g.get(vocab.column(t, "error"), pd.Series(False, index=g.index))
            errors[t] = int(error.fillna(False).astype(bool).sum())
            row[vocab.column(t, "failed_runs")] = int(failed.sum())
            row[vocab.column(t, "error_runs")] = errors[t]
        for task in vocab.exclusion_tasks:
            if rule_column(vocab, task) in g:
                row[rule_column(vocab, task)] = g[rule_column(vocab, task)].iloc[0]
        for task in vocab.exclusion_tasks if REFERENCE_MAPS in g else ():
            row[vocab.column(task, "excluded_runs")] = int(g[REFERENCE_MAPS].eq(0).sum())
        notes: dict[str, list[str]] = {}  # why a metric has no interval: its metrics
        for m in metrics:
            if m in g:
                row[m], lo, hi, note, seen = summaries.get((m, policy, budget), none)
                bounds = vocab.range_of(vocab.split(m)[1])
                row[f"{m}_lo"], row[f"{m}_hi"] = within(lo, hi, bounds)
                task, name = vocab.split(m)
                if errors.get(task) and vocab.metrics[name].failure is None:
                    note, seen = (
                        f"incomplete: {errors[task]} of {len(g)} runs could not be computed",
                        True,
                    )
                if note and seen:
                    notes.setdefault(note, []).append(m)
        row["note"] = "; ".join(f"{why}: {', '.join(ms)}" for why, ms in notes.items())
        out.append(row)
    t = with_tiers(pd.DataFrame(out), rows, vocab)
    if t.empty:
        return t
    order = t.apply(
        lambda r: (r["budget"] if r["budget"] > 0 else math.inf, vocab.order(r["method"])), axis=1
    )
    return t.loc[order.sort_values().index].reset_index(drop=True)


def errored(frame: pd.DataFrame, vocab: Vocabulary) -> set[str]:
    """The methods with a run that could not be computed (`counted`'s `error` of any
    task): a method that raised is neither tiered nor judged, whatever it scored."""
    cols = [c for c in (vocab.column(t, "error") for t in vocab.tasks) if c in frame]
    if not cols:
        return set()
    hit = frame[cols].fillna(False).astype(bool).any(axis=1)
    return set(frame.loc[hit, "method"])


def tier_column(metric: str) -> str:
    """Table 1's column of a metric's tiers."""
    return f"{metric}_tier"


def with_tiers(t: pd.DataFrame, rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Table 1 with the tiers of each task's first headline metric (`tier_column`): per
    budget and per category of what a method sees (`sees`: no method is tiered against
    one of the other category), among the budgeted methods that are no reference, over
    the (scene, seed) units every one of them has (`bench.report.power.tiers`:
    Holm-corrected Wilcoxon tests; 1 is the best's tier); empty for the others, and for a
    method run on fewer units than the rest (a partly run policy is never tiered over
    units it did not run) and a method with a run that could not be computed (`errored`)."""
    if t.empty:
        return t
    left_out = set(vocab.with_role("reference")) | errored(rows, vocab)
    for m in (m for m in vocab.first_headline() if m in rows):
        counted = solvable(rows, m, vocab)
        counted = counted[(counted["budget"] > 0) & ~counted["method"].isin(left_out)]
        counted = counted.assign(sees=counted["method"].map(vocab.sees))
        tier = {}
        for (budget, _), at in counted[counted["sees"] != ""].groupby(["budget", "sees"]):
            wide = at.pivot_table(index=["scene", "seed"], columns="method", values=m)
            counts = wide.count()  # a method run on fewer units is not tiered
            wide = wide.loc[:, (counts == counts.max()) & (counts > 0)].dropna()
            if wide.shape[1] >= 2 and len(wide):
                lower = m in vocab.lower_better()
                tier |= {(k, budget): v for k, v in tiers(wide, lower).items()}
        t[tier_column(m)] = [tier.get(k, math.nan) for k in zip(t["method"], t["budget"])]
    return t


def _units(rows: pd.DataFrame, budget: int, metric: str) -> tuple[np.ndarray, dict]:
    """The (scene, seed) units at `budget`: each unit's scene, and each method's values of
    `metric` over them (NaN where it has none)."""
    at = rows[rows["budget"] == budget]
    wide = at.pivot(index=["scene", "seed"], columns="method", values=metric).astype(float)
    scenes = wide.index.get_level_values("scene").to_numpy()
    return scenes, {m: wide[m].to_numpy() for m in wide.columns}


def _paired(
    rows: pd.DataFrame, pairs: list[tuple[str, str]], metrics, vocab: Vocabulary
) -> pd.DataFrame:
    """Policy minus baseline for each (policy, baseline) of `pairs`, per scene and pooled,
    per budget and metric, over the (scene, seed) units both ran; each row names what
    both see (`method_sees`, `baseline_sees`: a pair across categories says so)."""
    out = []
    lower = vocab.lower_better()
    for budget in sorted(b for b in pd.unique(rows["budget"]) if b > 0):
        for scope in [*pd.unique(rows["scene"]), "all scenes"]:
            part = rows if scope == "all scenes" else rows[rows["scene"] == scope]
            units = {m: _units(solvable(part, m, vocab), budget, m) for m in metrics if m in part}
            for policy, base in pairs:
                for m, (scenes, values) in units.items():
                    both = policy in values and base in values  # else n = 0: one is missing
                    d = values[policy] - values[base] if both else []
                    res = paired_difference(d, scenes if both else [], m in lower)
                    out.append(
                        {
                            "scene": scope,
                            "budget": budget,
                            "method": policy,
                            "baseline": base,
                            "method_sees": vocab.sees(policy),
                            "baseline_sees": vocab.sees(base),
                            "metric": m,
                            **res,
                        }
                    )
    return pd.DataFrame(out)


def paired(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """The headline policy (adaptive) minus every other baseline or contender, per scene
    and pooled, per budget and headline metric (`rows`: `headline_frame`)."""
    ranked = set(vocab.with_role("baseline", "contender")) - {HEADLINE_POLICY}
    others = [p for p in pd.unique(rows["method"]) if p in ranked]
    return _paired(rows, [(HEADLINE_POLICY, b) for b in others], vocab.headline_metrics(), vocab)


def paired_sfm(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """In the summary metrics (`Task.summary`) of the tasks the peers run (sfm: mAA and
    registered views), per scene and pooled, per budget (`rows`: `headline_frame`): every
    budgeted policy minus each peer held to the budget that sees what it sees
    (`CATEGORY_PEERS`; the oracle minus each), and
    every contender (and the oracle) minus every baseline. Cells stock COLMAP does not
    map are left out (`solvable`)."""
    present = list(pd.unique(rows["method"]))
    ranked = {*vocab.with_role("baseline", "contender"), *vocab.with_kind(GROUND_TRUTH)}
    policies = [p for p in present if p in ranked]
    truth = set(vocab.with_kind(GROUND_TRUTH))
    pairs = [
        (p, peer)
        for peer in CATEGORY_PEERS
        if peer in present
        for p in policies
        if p in truth or vocab.sees(p) == vocab.sees(peer)
    ]
    bases = [p for p in present if p in vocab.with_role("baseline")]
    pairs += [(p, b) for p in policies if p not in bases for b in bases]
    metrics = [m for n, t in vocab.tasks.items() if t.peers for m in vocab.summary_metrics(n)]
    if not pairs or not metrics:
        return pd.DataFrame()
    return _paired(rows, pairs, metrics, vocab)


def table2(rows: pd.DataFrame, pairs: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per scene (and pooled) and budget: adaptive, the best baseline of each headline metric
    and the paired difference to it, plus the oracle's completeness (`rows`:
    `headline_frame`)."""
    out = []
    metrics, lower = vocab.headline_metrics(), vocab.lower_better()
    if pairs.empty:  # no policy beside a baseline or peer (a grid of aliked-b alone)
        pairs = pd.DataFrame(columns=["scene", "budget", "baseline", "metric"])
    for budget in sorted(b for b in pd.unique(rows["budget"]) if b > 0):
        for scope in [*pd.unique(rows["scene"]), "all scenes"]:
            part = rows[rows["budget"] == budget]
            part = part if scope == "all scenes" else part[part["scene"] == scope]
            by_method = {
                m: solvable(part, m, vocab).groupby("method")[m] for m in metrics if m in part
            }
            means = pd.DataFrame({m: g.mean() for m, g in by_method.items()})
            counts = pd.DataFrame({m: g.count() for m, g in by_method.items()})
            row = {"scene": scope, "budget": budget}
            for m in (m for m in metrics if m in means):
                row[f"{HEADLINE_POLICY}_{m}"] = means[m].get(HEADLINE_POLICY, math.nan)
                row[f"{HEADLINE_POLICY}_{m}_n"] = counts[m].get(HEADLINE_POLICY, 0)
                baselines = vocab.with_role("baseline")
                base = means.loc[[p for p in baselines if p in means.index], m].dropna()
                best = (base.idxmin() if m in lower else base.idxmax()) if len(base) else ""
                row[f"best_baseline_{m}"] = base.get(best, math.nan) if best else math.nan
                row[f"best_baseline_{m}_policy"] = best
                row[f"best_baseline_{m}_n"] = counts[m].get(best, 0) if best else 0
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
                row[f"diff_{m}_note"] = r.get("note", "")
                row[f"diff_{m}_wtl"] = f"{r['wins']}/{r['ties']}/{r['losses']}" if len(p) else ""
                row[f"diff_{m}_n"] = r.get("n", 0)
            for truth in vocab.with_kind(GROUND_TRUTH):  # the reference of the shares
                for of in dict.fromkeys(vocab.shares().values()):
                    row[f"{truth}_{of}"] = (
                        means[of].get(truth, math.nan) if of in means else math.nan
                    )
            out.append(row)
    t = pd.DataFrame(out)
    # the column name Table 2 has had since its first version
    return t.rename(
        columns={
            "best_baseline_acc_completeness_pct_policy": "best_baseline_acc_completeness_policy",
        }
    )


def table_scenes(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per scene, policy and budget: means over seeds of every task's summary metrics
    (`Task.summary`; `rows`: `headline_frame`)."""
    cols = [m for n in vocab.tasks for m in vocab.summary_metrics(n) if m in rows]
    keys = ["scene", "method", "budget"]
    t = pd.DataFrame(
        {m: solvable(rows, m, vocab).groupby(keys, sort=False)[m].mean() for m in cols}
    )
    t = t.reindex(rows.groupby(keys, sort=False).size().index).reset_index()
    t.insert(3, "seeds", rows.groupby(keys, sort=False).size().values)
    if REFERENCE_MAPS in rows:
        excluded = rows[REFERENCE_MAPS].eq(0).groupby([rows[k] for k in keys], sort=False)
        for k, task in enumerate(vocab.exclusion_tasks):
            t.insert(4 + k, vocab.column(task, "excluded_seeds"), excluded.sum().astype(int).values)
    order = t.apply(lambda r: (r["scene"], r["budget"], vocab.order(r["method"])), axis=1)
    return t.loc[order.sort_values().index].reset_index(drop=True)


def frontend_cost(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Per policy: mean front-end ms of a run (detect + its signals + select) with the
    rig's poses (the `tri` task) and the mean ratio to texture-only over the units both
    ran; the same with the geometry from the images (the first task granted the images
    only, `Vocabulary.posefree_task`: sfm, `_posefree`) and the mean ratio of the
    pose-free to the posed front end over the units both ran."""
    parts = ["detect_ms", "signals_ms", "select_ms"]
    ranked = vocab.with_role("baseline", "contender")
    rows = df[df["protocol"].isin((HEADLINE[1], NO_PROTOCOL)) & df["method"].isin(ranked)]
    if rows.empty or not set(parts) <= set(rows):
        return pd.DataFrame()
    unit = ["scene", "seed", "budget", "method"]
    front = {
        task: rows[rows["task"] == task].set_index(unit)[parts].sum(axis=1) for task in vocab.tasks
    }
    out = []
    for policy in dict.fromkeys(rows["method"]):
        row = {"method": policy}
        posed_task, free_task = HEADLINE[0], vocab.posefree_task
        for task, suffix in ((posed_task, ""), (free_task, "_posefree")):
            f = front[task]
            units = f[f.index.get_level_values("method") == policy].droplevel("method")
            has_texture = "texture" in set(f.index.get_level_values("method"))
            tex = f.xs("texture", level="method") if has_texture else None
            row[f"frontend_ms{suffix}"] = units.mean() if len(units) else math.nan
            row[f"ratio_to_texture{suffix}"] = (
                (units / tex.reindex(units.index)).mean() if tex is not None else math.nan
            )
        posed = front[posed_task][front[posed_task].index.get_level_values("method") == policy]
        free = front[free_task][front[free_task].index.get_level_values("method") == policy]
        row["posefree_to_posed"] = (free / posed.reindex(free.index)).mean()
        out.append(row)
    t = pd.DataFrame(out)
    return t.iloc[t["method"].map(vocab.order).argsort(kind="stable")].reset_index(drop=True)


def equal_keypoints(rows: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """`table1_equal.csv`: every equal-count method (`<policy>@<peer>`, a per-view policy
    at the peer's own keypoint count in each view, `bench.backend.equal_count`) against its
    peer, per scene and pooled, per budget, in the summary metrics of the tasks the peers
    run, with the paired difference (`_paired`) and both methods' mean keypoints per view
    (`rows`: `headline_frame`); empty without such a method and its peer."""
    present = set(pd.unique(rows["method"]))
    pairs = [
        (m, equal_parts(m)[1])
        for m in vocab.with_kind(EQUAL_COUNT)
        if m in present and equal_parts(m)[1] in present
    ]
    metrics = [m for n, t in vocab.tasks.items() if t.peers for m in vocab.summary_metrics(n)]
    if not pairs or not metrics:
        return pd.DataFrame()
    out = _paired(rows, pairs, metrics, vocab)
    task = vocab.posefree_task
    count = vocab.column(task, "keypoints_per_view") if task else ""
    if count in rows:
        kpv = rows.groupby(["method", "budget"])[count].mean()
        for side, col in (("method", "method_kpv"), ("baseline", "peer_kpv")):
            out[col] = [kpv.get((m, b), math.nan) for m, b in zip(out[side], out["budget"])]
    return out.rename(columns={"baseline": "peer", "baseline_sees": "peer_sees"})
