"""The results page: `README.md` of a results folder, written by `bench plot` (and so by
`bench run`) from the files the report wrote beside it. Every number on it is read from
those files: the tables (computed from `runs.csv` alone), `manifest.json` (the run's
machine, versions and seconds) and `config.json` (its settings). Nothing on it is typed
by hand, so it never disagrees with its folder; `bench publish` copies it with the rest.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from pandas.api.types import is_numeric_dtype

from bench.binding import read_vocabulary
from bench.failures import outcomes
from bench.report import nbv
from bench.report.categories import headline, unjudged, verdict_sentences
from bench.report.cost import frontier_only
from bench.report.pools import recommendation
from bench.report.power import min_units
from bench.report.text import ci, column_format, signed
from bench.report.text import num as _num
from bench.report.text import table as _table
from bench.report.transfer import TRANSFER_TEXT, verdicts
from bench.results import (
    CONFIG,
    FIGURE2,
    FIGURE3,
    FIGURE_BUDGET,
    FIGURE_COST,
    FIGURE_TRANSFER,
    FIGURE_VIEWS,
    MANIFEST,
    PAIRED,
    PAIRED_SFM,
    RUNS,
    TABLE1,
    TABLE1_EQUAL,
    TABLE2,
    TABLE_COST,
    TABLE_POOLS,
    TRANSFER,
    VERDICTS,
    png,
)
from bench.vocabulary import (
    CATEGORY_PEERS,
    HEADLINE,
    HEADLINE_BUDGET,
    HEADLINE_POLICY,
    ORACLE,
    RECOMPUTED_TRUTH,
    SEES,
    Vocabulary,
)

POOLED = ("all", "all scenes")
"""How the tables name the pooled rows."""
TASK_COLUMNS = 3
"""How many of a task's Table 1 columns (its first, in the task registry's order) the
page shows; the CSV has them all."""
NAMES = (
    "A method is named by its key (what `--methods` takes; `vocabulary.json` has its label). "
    "A metric is named as in `runs.csv` (its rows hold the task in `task`), prefixed with "
    f"its task in every table but the headline task's ({HEADLINE[0]}): `maa` of the sfm "
    "rows is `sfm_maa`. `runs`: the runs a task's means count."
)
"""How the page names methods and metrics, said once above Table 1."""
ORACLE_SAID = (
    f" `{ORACLE}` is a reference selection made with the ground truth (per view, the B "
    "candidates that give the most true tracks of three or more views whose descriptors "
    "match), scored like every method: it is not a bound, and a policy may map or complete "
    "more than it (docs/protocol.md, Oracle)."
)
"""What the oracle is and is not, said with the names where it ran."""
ORACLE_RECOMPUTED = (
    " Here its truth was recomputed on the machine that ran (`ground_truth`: rendered, "
    "recomputed; the views are the reference renders), which can differ from the reference "
    "machine's in a few pixels' last bits: the oracle alone selects with the truth, so its "
    "rows alone may move between machines (docs/scenes.md, The reference renders)."
)
"""The oracle's caveat, said where its rows read recomputed truth."""
FIGURES = {
    png(FIGURE3): "Headline metrics per method at the headline budget, 95% intervals",
    png(FIGURE_BUDGET): "Each headline metric against the budget",
    png(FIGURE2): f"Figure 2: the {HEADLINE_POLICY} selection and its points coloured by error",
    png(FIGURE_TRANSFER): "The rendered ranking against each dataset's",
    png(FIGURE_COST): (
        "Quality against cost: a method above its category's frontier (colmap-b for its own "
        "image, colmap-tracks-b for other views; black lines over 128-2048) is worth its cost"
    ),
    png(FIGURE_VIEWS): "Next views: each score against the views added, per chooser",
}


def _read(results: Path, name: str) -> pd.DataFrame:
    path = results / name
    return pd.read_csv(path) if path.is_file() else pd.DataFrame()


def _json(results: Path, name: str) -> dict:
    path = results / name
    return json.loads(path.read_text()) if path.is_file() else {}


def _text(x, missing: str = "n/a") -> str:
    return x if isinstance(x, str) else missing


def _interval(
    row: pd.Series, col: str, lo: str = "", hi: str = "", note: str = "", fmt=_num
) -> str:
    """`mean [lo, hi]` in the column's format `fmt`, or the mean and the table's note on
    why it has no interval."""
    why = row.get(note) if note else None
    return ci(row.get(col), row.get(lo or f"{col}_lo"), row.get(hi or f"{col}_hi"), why, fmt)


def _format(frame: pd.DataFrame, cols, bounds=(), difference: bool = False):
    """One format for the numbers of the columns `cols` of `frame`, and of its intervals'
    `bounds` columns (`bench.report.text.column_format`); signed for a `difference`."""
    values = [frame[c].to_numpy(object) for c in cols if c in frame]
    fmt = column_format(
        np.concatenate(values) if values else [], *(frame[c] for c in bounds if c in frame)
    )
    return signed(fmt) if difference else fmt


def _run_section(manifest: dict, runs: pd.DataFrame) -> list[str]:
    host = manifest.get("host", {})
    versions = ", ".join(f"{k} {v}" for k, v in manifest.get("versions", {}).items())
    commits = ", ".join(c[:7] for c in manifest.get("git_commit", []))
    out = ["## The run", ""]
    out.append(f"- rows: {len(runs)} ({(runs.get('status') == 'failed').sum()} failed)")
    variant = manifest.get("variant") or "none (nothing rendered)"
    out.append(f"- commit: {commits or 'n/a'}; render variant: {variant}")
    out.append(f"- machine: {host.get('platform', 'n/a')}, {host.get('cpus', 'n/a')} CPUs")
    out.append(f"- versions: {versions or 'n/a'}")
    cost = rows_cost(runs)
    if cost:
        out.append(
            f"- the cost of these rows, from their own timing columns: {_num(round(cost))} s of "
            "worker time (a scene's front end once, a unit's selection, matching and "
            "verification once, each row's task; a row reused from a cache counts what it cost "
            "when it was computed), beside the invocations' wall seconds below"
        )
    seconds = manifest.get("seconds", {})
    if seconds:
        out += ["", "Seconds per stage (summed over the invocations that computed these rows):", ""]
        out += _table(list(seconds), [[_num(round(v)) for v in seconds.values()]])
    return out + _wall_section(manifest)


SHARED_MS = {("scene", "seed", "bag"): ("detect_ms", "signals_ms")}
SHARED_MS |= {("scene", "seed", "bag", "method", "budget"): ("select_ms", "match_ms", "verify_ms")}
"""The stages rows share, by what shares them: a scene's front end, a unit's selection,
matching and verification (each row repeats them)."""


def rows_cost(runs: pd.DataFrame) -> float:
    """Seconds of worker time the rows' own timing columns add up to: each shared stage
    once per what shares it (`SHARED_MS`), every row's task."""
    if "task_ms" not in runs:
        return 0.0
    total = float(np.nansum(runs["task_ms"].to_numpy(float)))
    for keys, stages in SHARED_MS.items():
        keys, stages = [k for k in keys if k in runs], [c for c in stages if c in runs]
        if stages:
            once = runs.groupby(keys, dropna=False)[stages].max().to_numpy(float)
            total += float(np.nansum(once))
    return total / 1000


def _wall_section(manifest: dict) -> list[str]:
    """Each invocation's wall seconds per phase beside the workers and cores that ran it
    (`benchmarks/profile.py` gives the whole profile)."""
    timed = [i for i in manifest.get("invocations", []) if isinstance(i, dict) and i.get("wall")]
    if not timed:
        return []
    phases = list(dict.fromkeys(k for i in timed for k in i["wall"]))
    rows = [
        [
            str(i.get("id", "n/a")),
            str(i.get("cluster", {}).get("workers", "n/a")),
            str(i.get("cluster", {}).get("cores", "n/a")),
            _num(i.get("rows")),
            *(_num(round(i["wall"][k])) if k in i["wall"] else "n/a" for k in phases),
        ]
        for i in timed
    ]
    out = ["", "Wall seconds per phase, per invocation, with the workers and cores it ran on:", ""]
    return out + _table(["invocation", "workers", "cores", "rows", *phases], rows)


def _grid_section(runs: pd.DataFrame, config: dict) -> list[str]:
    out = ["## Grid and settings", ""]
    for col in ("scene", "seed", "method", "budget", "task", "protocol"):
        values = sorted(set(runs[col].astype(str)), key=lambda v: (len(v), v))
        out.append(f"- {col}: {', '.join(values)}")
    settings = config.get("settings") or {}
    if settings:
        out += ["", f"<details><summary>Settings ({CONFIG})</summary>", "", "```"]
        out += [json.dumps(settings, indent=1, sort_keys=True), "```", "</details>"]
    return out


def _table1_section(
    t1: pd.DataFrame, vocab: Vocabulary, title: str, recomputed: bool = False
) -> list[str]:
    if t1.empty:
        return []
    oracle = ORACLE in set(t1["method"])
    said = ORACLE_SAID + (ORACLE_RECOMPUTED if recomputed else "") if oracle else ""
    out = [f"## {title}", "", NAMES + said, ""]
    for task in vocab.tasks.values():
        prefix = "" if task.name == HEADLINE[0] else f"{task.name}_"
        cols = [prefix + c for c in task.metrics[:TASK_COLUMNS] if prefix + c in t1]
        rows = t1.dropna(subset=cols, how="all") if cols else t1.iloc[0:0]
        if rows.empty:
            continue
        header = ["method", "budget", "runs", *cols, "why an interval is missing"]
        fmt = {c: _format(rows, [c], [f"{c}_lo", f"{c}_hi"]) for c in cols}
        body = {
            b: [
                [str(r["method"]), _num(r["budget"]), _runs(r, vocab, task.name)]
                + [_interval(r, c, fmt=fmt[c]) for c in cols]
                + [_why(r.get("note"), cols)]
                for _, r in at.iterrows()
            ]
            for b, at in rows.groupby("budget")
        }
        main = [r for b, rs in body.items() if b in (0, HEADLINE_BUDGET) for r in rs]
        rest = [r for b, rs in body.items() if b not in (0, HEADLINE_BUDGET) for r in rs]
        out += [f"### `{task.name}`: {task.doc}", ""] + _table(header, main or rest) + [""]
        if main and rest:
            out += ["<details><summary>Other budgets</summary>", ""]
            out += _table(header, rest) + ["", "</details>", ""]
    return out


def _runs(r: pd.Series, vocab: Vocabulary, task: str) -> str:
    """The runs a task's means count (those the exclusion rule leaves out not), and how
    many of them could not be computed (scored at their failure value)."""
    excluded = r.get(vocab.column(task, "excluded_runs"))
    used = r["runs"] - (excluded if pd.notna(excluded) else 0)
    errors = r.get(vocab.column(task, "error_runs"))
    errors = errors if pd.notna(errors) else 0
    return _num(used) + (f" ({_num(errors)} could not be computed)" if errors else "")


def brief_table1(t1: pd.DataFrame, vocab: Vocabulary) -> str:
    """Table 1 as `bench run` prints it: each method's key (what `--methods` takes), its
    budget and, per task, the runs its means count and its first headline metric, as the
    page has them (the page and table1.csv have the rest)."""
    out = pd.DataFrame({"method": t1["method"], "budget": t1["budget"]})
    for name, task in vocab.tasks.items():
        col = vocab.column(name, task.headline[0]) if task.headline else None
        if col not in t1 or t1[col].isna().all():
            continue
        shown = t1[col].notna()
        out[f"{name}_runs"] = [
            _runs(r, vocab, name) if s else "-" for (_, r), s in zip(t1.iterrows(), shown)
        ]
        out[col] = [_num(v) for v in t1[col]]
    return out.to_string(index=False)


def _why(note, cols: list[str]) -> str:
    """The reasons of a Table 1 `note` (`reason: metric, ...; ...`) that apply to `cols`."""
    reasons = []
    for part in _text(note, "").split("; "):
        why, _, metrics = part.rpartition(": ")
        if why and set(metrics.split(", ")) & set(cols):
            reasons.append(why)
    return "; ".join(reasons)


def _tiers_section(t1: pd.DataFrame, vocab: Vocabulary) -> list[str]:
    """Which methods cannot be told apart, per tiered metric at the headline budget
    (Table 1's `<metric>_tier`: Holm-corrected Wilcoxon tests, docs/protocol.md), each
    tier best first."""
    cols = [c for c in t1.columns if c.endswith("_tier") and t1[c].notna().any()]
    if not cols:
        return []
    budgets = sorted(b for b in t1["budget"].unique() if b > 0)
    budget = HEADLINE_BUDGET if HEADLINE_BUDGET in budgets else budgets[len(budgets) // 2]
    at = t1[t1["budget"] == budget]
    out = [
        f"## Tiers at B = {budget}: methods that cannot be told apart",
        "",
        "Tier 1 is the best method by mean and every method not significantly different "
        "from it (two-sided Wilcoxon signed-rank tests over the units every method has, "
        "Holm-corrected at 0.05); the next tier starts at the best method left. Each tier "
        "best first. Tiers are per category of what a selection sees (`sees`): no method "
        "is tiered against one of the other category.",
        "",
    ]
    for col in cols:
        metric = col.removesuffix("_tier")
        best = [True, metric in vocab.lower_better()]
        ranked = at.dropna(subset=[col]).sort_values([col, metric], ascending=best, kind="stable")
        for sees, part in ranked.groupby(ranked["method"].map(vocab.sees), sort=False):
            groups = part.groupby(col, sort=True)["method"].agg(", ".join)
            tiers = "; ".join(f"{int(k)}: {v}" for k, v in groups.items())
            n = len(part)
            out.append(
                f"- `{metric}`, sees `{sees}`: {tiers} ({n} methods: with fewer than "
                f"{min_units(n)} units no two of them can be told apart, one tier)"
            )
    return out + [""]


def _table2_section(t2: pd.DataFrame) -> list[str]:
    """One row per scene and metric at the headline budget (every budget is in the CSV)."""
    if t2.empty:
        return []
    metrics = [
        c[len("diff_") : -len("_lo")] for c in t2 if c.startswith("diff_") and c.endswith("_lo")
    ]
    at = t2[t2["budget"] == HEADLINE_BUDGET] if (t2["budget"] == HEADLINE_BUDGET).any() else t2
    header = ["scene", "metric", HEADLINE_POLICY, "best baseline", "difference [95%]", "w/t/l"]
    header.append(f"runs ({HEADLINE_POLICY} / baseline / paired)")
    mine = _format(at, [f"{HEADLINE_POLICY}_{m}" for m in metrics])
    best = _format(at, [f"best_baseline_{m}" for m in metrics])
    bounds = [f"diff_{m}{s}" for m in metrics for s in ("_lo", "_hi")]
    diff = _format(at, [f"diff_{m}" for m in metrics], bounds, difference=True)
    body = []
    for _, r in at.iterrows():
        for m in metrics:
            winner = r.get(
                f"best_baseline_{m}_policy", r.get(f"best_baseline_{m.removesuffix('_pct')}_policy")
            )
            runs = [f"{HEADLINE_POLICY}_{m}_n", f"best_baseline_{m}_n", f"diff_{m}_n"]
            body.append(
                [
                    str(r["scene"]),
                    m,
                    mine(r.get(f"{HEADLINE_POLICY}_{m}")),
                    f"{best(r.get(f'best_baseline_{m}'))} ({_text(winner)})",
                    _interval(r, f"diff_{m}", note=f"diff_{m}_note", fmt=diff),
                    _text(r.get(f"diff_{m}_wtl")),
                    " / ".join(_num(r.get(c)) for c in runs),
                ]
            )
    title = f"## Table 2: {HEADLINE_POLICY} against the best baseline, budget {_num(at['budget'].iloc[0])}"
    said = (
        "Each mean is over its method's own runs, the difference over the runs both have "
        "(a run without a value, such as the rmse of a run that triangulated nothing, is in "
        "neither): the last column counts each."
    )
    return [title, "", said, ""] + _table(header, body) + [""]


def _paired_section(
    paired: pd.DataFrame, vocab: Vocabulary, title: str, baseline: str | None
) -> list[str]:
    """The pooled rows (all scenes) at the headline budget in each task's first headline
    metric (`Vocabulary.first_headline`; the CSVs have them all), against `baseline` if
    given."""
    if paired.empty:
        return []
    pooled = paired["scene"].isin(POOLED) & (paired["budget"] == HEADLINE_BUDGET)
    rows = paired[pooled & paired["metric"].isin(vocab.first_headline())]
    if baseline is not None:
        rows = rows[rows["baseline"] == baseline]
    if rows.empty:
        return []
    header = ["method (sees)", "baseline (sees)", "metric", "n", "mean difference [95%]", "w/t/l"]
    fmt = _format(rows, ["mean_diff"], ["lo", "hi"], difference=True)
    body = [
        [
            f"{r['method']} ({r.get('method_sees', 'n/a')})",
            f"{r['baseline']} ({r.get('baseline_sees', 'n/a')})",
            str(r["metric"]),
            _num(r["n"]),
            _interval(r, "mean_diff", "lo", "hi", "note", fmt),
            f"{_num(r['wins'])}/{_num(r['ties'])}/{_num(r['losses'])}",
        ]
        for _, r in rows.iterrows()
    ]
    return [f"## {title}", ""] + _table(header, body) + [""]


def _equal_section(equal: pd.DataFrame) -> list[str]:
    """Table 1e: each equal-count method against its peer at the same keypoints per view,
    pooled, every budget and metric; its first sentence, the headline budget's paired
    differences in the table's first metric (the sfm task's mAA)."""
    rows = equal[equal["scene"].isin(POOLED)] if not equal.empty else equal
    if rows.empty:
        return []
    first = rows["metric"].iloc[0]
    head = rows[(rows["budget"] == HEADLINE_BUDGET) & (rows["metric"] == first)]
    fmt = _format(rows, ["mean_diff"], ["lo", "hi"], difference=True)
    said = "; ".join(
        f"`{r['method']}` {_interval(r, 'mean_diff', 'lo', 'hi', 'note', fmt)} against "
        f"`{r['peer']}` ({_num(r['method_kpv'])} and {_num(r['peer_kpv'])} keypoints per view)"
        for _, r in head.iterrows()
    )
    out = ["## Table 1e: at equal keypoints per view (peers that hold more than B)", ""]
    if said:
        out += [
            f"At the peer's own count in each view, {first} at {HEADLINE_BUDGET}, paired "
            f"difference [95%]: {said}.",
            "",
        ]
    header = ["method", "peer", "budget", "metric", "keypoints/view", "n", "difference", "w/t/l"]
    body = [
        [
            f"`{r['method']}`",
            f"`{r['peer']}`",
            _num(r["budget"]),
            str(r["metric"]),
            f"{_num(r['method_kpv'])} / {_num(r['peer_kpv'])}",
            _num(r["n"]),
            _interval(r, "mean_diff", "lo", "hi", "note", fmt),
            f"{_num(r['wins'])}/{_num(r['ties'])}/{_num(r['losses'])}",
        ]
        for _, r in rows.iterrows()
    ]
    return out + _table(header, body) + [""]


def _verdicts_section(verdicts: pd.DataFrame, missing: list[str]) -> list[str]:
    """Each category of `sees` against its peer, every budget (`verdicts.csv`), and the
    methods no verdict judges (`missing`: `bench.report.categories.unjudged`)."""
    said = verdict_sentences(verdicts)
    if not said and not missing:
        return []
    out = ["## Verdicts per category: each against a peer that sees what it sees", ""]
    out += [f"- `{k}`: {v}" for k, v in SEES.items()] + [""]
    return out + [f"- {line}" for line in said + [m[0].upper() + m[1:] for m in missing]] + [""]


def _pools_section(pools: pd.DataFrame, vocab: Vocabulary) -> list[str]:
    """Which detector and which selection at a budget (`table_pools.csv`), where the grid
    ran on several pools."""
    said = recommendation(pools, vocab)
    if not said:
        return []
    head = "## Pools: which detector and which selection at a budget (table_pools.csv)"
    return [head, ""] + [f"- {line}" for line in said] + [""]


def _cost_section(cost: pd.DataFrame) -> list[str]:
    """Table 1c: what each method matched and the time it took, at the headline budget
    (`table_cost.csv` has every budget)."""
    if cost.empty:
        return []
    budgets = sorted(cost["budget"].unique())
    budget = HEADLINE_BUDGET if HEADLINE_BUDGET in budgets else budgets[len(budgets) // 2]
    at = cost[cost["budget"] == budget]
    metrics = [c for c in at.columns[at.columns.get_loc("ms_per_view") + 1 :]]
    header = ["method", "sees", "first pass kpv", "final kpv", "ms per view", *metrics]
    body = [
        [f"`{r['method']}`", str(r["sees"]), _num(r["first_pass_kpv"]), _num(r["final_kpv"])]
        + [_num(r["ms_per_view"]), *(_num(r[m]) for m in metrics)]
        for _, r in at.iterrows()
    ]
    said = (
        f"At B = {_num(budget)}, per method: the keypoints per view matched before choosing "
        "(a first pass; 0 for a selection that sees its own image) and kept, and the front "
        "end plus matching milliseconds per view of a pose-free run (detection, the signals "
        "read, the selection with its first pass, matching and verification)."
    )
    return ["## Table 1c: the cost", "", said, ""] + _table(header, body) + [""]


def _transfer_section(transfer: pd.DataFrame) -> list[str]:
    if transfer.empty:
        return []
    shown = [c for c in transfer.columns if not c.startswith("top_")]
    text = set(TRANSFER_TEXT) | {c for c in shown if not is_numeric_dtype(transfer[c])}
    fmt = {c: _num if c in text else column_format(transfer[c]) for c in shown}
    body = [
        [_as_in_csv(v, c in text, fmt[c]) for c, v in zip(shown, r)] for r in transfer[shown].values
    ]
    said = verdicts(transfer, _transfer_budget(transfer)) if "matched" in transfer else []
    out = ["## Transfer: the rendered ranking on each dataset", ""]
    out += [f"- {line}" for line in said] + ([""] if said else [])
    out += [TRANSFER_COLUMNS, ""]
    return out + _table(shown, body) + [""]


def _as_in_csv(value, text: bool, fmt) -> str:
    """A transfer.csv value as the CSV has it: True/False, empty text, numbers in their
    column's format."""
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if text:
        return "" if pd.isna(value) else str(value)
    return fmt(value)


TRANSFER_COLUMNS = (
    "Per dataset, regime (`rendered_views`; `matched`: the regime nearest the set's view "
    "count), metric and budget: `kendall_tau` [`tau_lo`, `tau_hi`] of the set's ranking of "
    "the methods against the renders'; `rel_rendered` and `rel_dataset` the split-half "
    "reliability of each ranking; `ceiling` the square root of their product, the highest "
    "tau their noise allows; `tau_photos` the other sets' ranking against this set's (the "
    "real-to-real baseline, empty with one set); `signs_agree` of `signs_decided` the "
    "methods whose sign against `colmap-b` is the same on the renders and the set (`_photos`: "
    "in the other sets); `biggest_movers` the methods whose rank moves most, rendered rank "
    "-> set rank (1: the best)."
)


def _transfer_budget(transfer: pd.DataFrame) -> int:
    """256 when the transfer table has it, else its middle budget."""
    budgets = sorted(transfer["budget"].unique())
    return HEADLINE_BUDGET if HEADLINE_BUDGET in budgets else budgets[len(budgets) // 2]


def _exclusions(runs: pd.DataFrame, t1: pd.DataFrame, vocab: Vocabulary) -> list[str]:
    out = ["## What was excluded or failed, and why", ""]
    failed = runs[runs["status"] == "failed"]
    if failed.empty:
        out.append("- no row failed")
    else:
        reasons = failed["failure"].fillna("").str.split(":").str[0].value_counts()
        out += [f"- {n} rows failed: {why}" for why, n in reasons.items()]
        out += [f"- {outcomes(runs)}"] if outcomes(runs) else []
    for task in vocab.exclusion_tasks:
        excluded = vocab.column(task, "excluded_runs")
        if excluded in t1 and t1[excluded].fillna(0).sum():
            n = int(t1.groupby("method")[excluded].max().max())
            out.append(
                f"- up to {n} runs per method left out of the {task} means: their (scene, "
                "seed) is not mapped by stock COLMAP with all its features (`reference_maps` 0)"
            )
    return out + [""]


def results_page(results: Path, runs: pd.DataFrame | None = None) -> str:
    """The page of a results folder, from its files (`runs`: its rows, if already read); the
    cost figure's frontier rows (`bench.report.cost.frontier_only`) count in the run and the
    grid, and enter no other section."""
    results = Path(results)
    everything = pd.read_csv(results / RUNS) if runs is None else runs
    runs = everything[~frontier_only(everything)]
    vocab = read_vocabulary(results)
    t1 = _read(results, TABLE1)
    out = [
        f"# Results: `{results.name}`",
        "",
        f"Written by `bench plot` from this folder's `{RUNS}`, `{MANIFEST}` and "
        f"`{CONFIG}`; every number below is in those files or the tables beside them. "
        "Do not edit: the next `bench plot` rewrites it.",
        "",
    ]
    verdicts = _read(results, VERDICTS)
    said = headline(verdicts)
    out += [said, ""] if said else []
    out += _run_section(_json(results, MANIFEST), everything) + [""]
    out += _grid_section(everything, _json(results, CONFIG)) + [""]
    recomputed = RECOMPUTED_TRUTH in set(runs.get("ground_truth", pd.Series(dtype=str)).dropna())
    out += _table1_section(t1, vocab, "Table 1: means over runs, 95% intervals", recomputed)
    out += _tiers_section(t1, vocab)
    out += _verdicts_section(verdicts, unjudged(vocab, set(runs["method"])))
    out += _pools_section(_read(results, TABLE_POOLS), vocab)
    out += _cost_section(_read(results, TABLE_COST))
    out += _equal_section(_read(results, TABLE1_EQUAL))
    ran = set(t1["method"]) if "method" in t1 else set()  # a method not run has no section
    if HEADLINE_POLICY in ran:
        out += _table2_section(_read(results, TABLE2))
        out += _paired_section(
            _read(results, PAIRED),
            vocab,
            f"Paired: {HEADLINE_POLICY} against every method, all scenes",
            None,
        )
    for peer in (p for p in CATEGORY_PEERS if p in ran):
        out += _paired_section(
            _read(results, PAIRED_SFM),
            vocab,
            f"Paired: every method that sees what `{peer}` sees (`{vocab.sees(peer)}`) "
            "against it (held to the budget), all scenes, in the tasks it runs",
            peer,
        )
    out += nbv.page_section(results, vocab)
    out += _transfer_section(_read(results, TRANSFER))
    figures = [(n, t) for n, t in FIGURES.items() if (results / n).is_file()]
    if figures:
        out += ["## Figures", ""] + [f"![{t}]({n})" + "\n" for n, t in figures]
    out += _exclusions(runs, t1, vocab)
    out.append(
        "Every table is a CSV beside this page with every column; the definitions are in "
        "the project's `docs/protocol.md`."
    )
    return "\n".join(out) + "\n"
