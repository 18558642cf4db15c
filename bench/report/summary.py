"""The repository README's results section, written from the published snapshots' files
alone (`bench publish` rewrites it between `BEGIN` and `END`), so that it cannot go stale.

Per regime snapshot, task (its first headline metric on `Table 1`, `PRIMARY`) and category
(what a selection sees, `bench.vocabulary.SEES`: `image` or `views`), at `HEADLINE_BUDGET`:
the policy (a baseline or a contender) with the highest mean leads; beside it the
category's peer (`PEER`: the stock-COLMAP method that sees what it sees, else `colmap-b`,
named), the paired difference of the leader minus that peer pooled over the snapshot's
cells with its 95 % interval, and the cells won, tied and lost (`paired_sfm.csv`). The
published photo sets' folder, where there is one, gives rows of its own (`PHOTO_ROWS`, a bag
is a cell) and, from its `transfer.csv`, a table row per set, task and category: whether
the renders predict its ranking as well as the other sets do
(`bench.report.transfer.prediction`). The next-views snapshot, where there is one, gives
its chooser's pooled paired gains (`_nbv_rows`), and the cross-pool snapshot, where there
is one, each category's leader across pools at each budget (`_pools_rows`).
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.binding import read_vocabulary
from bench.report.transfer import CANNOT_TELL, prediction
from bench.results import TABLE1, TABLE3, TABLE_POOLS, TRANSFER, VERDICTS
from bench.vocabulary import HEADLINE_BUDGET, Vocabulary

BEGIN = "<!-- results: written by `bench publish --readme` from the published snapshots -->"
END = "<!-- end of the written results -->"
POOLED = "all scenes"
PHOTO_ROWS = "photographs"
"""The regime column of the photo sets' rows (their bags pooled: a bag is a cell)."""


def _num(x: float, signed: bool = False, digits: int = 3) -> str:
    if x is None or math.isnan(x):
        return "n/a"
    return f"{x:+.{digits}f}" if signed else f"{x:.{digits}f}"


def _verdicts(snapshot: Path) -> pd.DataFrame:
    """A snapshot's `verdicts.csv` (empty where it has none)."""
    path = Path(snapshot) / VERDICTS
    return (
        pd.read_csv(path, keep_default_na=False, na_values=[""])
        if path.is_file()
        else (pd.DataFrame())
    )


def _task(vocab: Vocabulary, metric: str) -> str:
    """The task whose first headline metric `metric` is, as the tables name it."""
    return next(
        (n for n, t in vocab.tasks.items() if vocab.column(n, t.headline[0]) == metric), metric
    )


def _rows(snapshot: Path, regime: str) -> list[str]:
    """The table's rows of a snapshot at `HEADLINE_BUDGET`: its `verdicts.csv`, the report's
    one choice of each category's leader and peer (`bench.report.categories`)."""
    vocab, v = read_vocabulary(snapshot), _verdicts(snapshot)
    if v.empty:
        return []
    out = []
    for r in v[v["budget"] == HEADLINE_BUDGET].itertuples():
        wtl = f"{r.wins}/{r.ties}/{r.losses}"
        out.append(
            f"| {regime} | {_task(vocab, r.metric)} ({r.metric}) | {r.sees} | `{r.policy}` "
            f"{_num(r.policy_mean)} | `{r.peer}` {_num(r.peer_mean)} | {_num(r.mean_diff, True)} "
            f"[{_num(r.lo, True)}, {_num(r.hi, True)}] | {wtl} | {r.verdict} |"
        )
    return out


def _advice(snapshot: Path, regime: str) -> list[str]:
    """One sentence per category of a snapshot: which method to use at each budget and
    metric, from its `verdicts.csv`: the leader where it is above its peer, else the peer
    (nothing of the category beats it there)."""
    vocab, v = read_vocabulary(snapshot), _verdicts(snapshot)
    out = []
    for sees, rows in v.groupby("sees", sort=False) if len(v) else []:
        said = []
        for metric, at in rows.groupby("metric", sort=False):
            picks: dict[str, list[str]] = {}
            for r in at.sort_values("budget").itertuples():
                pick = r.policy if r.verdict == "above" else r.peer
                picks.setdefault(pick, []).append(_num(r.budget, digits=0))
            which = ", ".join(f"`{m}` (B = {', '.join(bs)})" for m, bs in picks.items())
            said.append(f"for {_task(vocab, metric)} {which}")
        out.append(f"- {regime}, `{sees}` selections: use " + "; ".join(said) + ".")
    return out


def results_section(
    snapshots: dict[str, Path],
    photos: Path | None,
    nbv: Path | None = None,
    pools: dict[str, Path] | None = None,
) -> str:
    """The README's results section (module docstring) from the regime snapshots
    (`{regime name: folder}`, those that exist), the published photo sets' folder, the
    next-views snapshot's and the cross-pool snapshots' (`{renders or photographs:
    folder}`, those that exist)."""
    found = {r: Path(f) for r, f in snapshots.items() if (Path(f) / TABLE1).is_file()}
    if not found:
        raise BenchError("no published snapshot with a table1.csv: nothing to summarise")
    lines = [
        f"At {HEADLINE_BUDGET} keypoints per view, the policy that leads each category of what",
        "its selection sees (`image`: its own view's; `views`: other views, through a first",
        "pass of matches), and the category's stock-COLMAP peer at the same budget; the",
        "difference is paired over the snapshot's cells (95 % interval; cells won/tied/lost;",
        f"the `{PHOTO_ROWS}` rows pool the published photo sets' bags, a bag a cell):",
        "",
        "| regime | task (metric) | sees | leads | peer | leader - peer | won/tied/lost "
        "| verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    folders = dict(found)
    if photos is not None and (Path(photos) / TABLE1).is_file():
        folders[PHOTO_ROWS] = Path(photos)
    for regime, folder in folders.items():
        lines += _rows(folder, regime)
    lines += [
        "",
        "Which method to use (each category's leader where its interval is above the peer's,",
        "else the peer itself: nothing of the category beats it there; from `verdicts.csv`):",
        "",
    ]
    for regime, folder in folders.items():
        lines += _advice(folder, regime)
    lines.append("")
    tables = {k: Path(f) for k, f in (pools or {}).items() if (Path(f) / TABLE_POOLS).is_file()}
    if tables:
        lines += _pools_rows(tables)
    if photos is not None and (Path(photos) / TRANSFER).is_file():
        vocab = read_vocabulary(next(iter(found.values())))
        lines += _transfer_rows(pd.read_csv(Path(photos) / TRANSFER), Path(photos), vocab)
    else:
        where = "none" if photos is None else Path(photos).as_posix()
        lines += [
            f"No snapshot of the photo sets is published ({where}): whether the ranking",
            "holds on photographs is not stated here (docs/datasets.md says how to measure it).",
        ]
    if nbv is not None and (Path(nbv) / TABLE3).is_file():
        lines += _nbv_rows(pd.read_csv(Path(nbv) / TABLE3), Path(nbv))
    return "\n".join(lines) + "\n"


def _pools_rows(tables: dict[str, Path]) -> list[str]:
    """Per snapshot (`{label: folder}` of those with a `table_pools.csv`,
    `bench.report.pools`), budget and task: each category's leader across pools, its paired
    difference from `colmap-b` and, for a selection, from its own pool's top-B."""
    first = next(iter(tables.values()))
    vocab = read_vocabulary(first)
    pools = sorted({p for f in tables.values() for p in pd.read_csv(f / TABLE_POOLS)["pool"]})
    where = ", ".join(f"{f.as_posix()}/README.md ({label})" for label, f in tables.items())
    out = [
        "Which detector and which selection, from grids on several pools (a pool: its",
        f"detector/matcher; {', '.join(f'`{p}`' for p in pools)}):",
        "per budget and task, each category's leader across pools, minus `colmap-b` and",
        "minus its own pool's top-B (paired over the cells; `itself`: it is that top-B; SIFT's",
        f"is `colmap-b`). Pages: {where}.",
        "",
        "| on | B | task (metric) | `image` leads (pool) | - `colmap-b` | - own top-B "
        "| `views` leads (pool) | - `colmap-b` | - own top-B |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    lower, tasks = vocab.lower_better(), list(vocab.tasks)
    leaders: dict = {}
    for label, folder in tables.items():
        table = pd.read_csv(folder / TABLE_POOLS)
        order = [
            tasks.index(_task(vocab, m)) if _task(vocab, m) in tasks else 99
            for m in table["metric"]
        ]
        table = table.assign(task_order=order)
        for (budget, _, metric), at in table.groupby(["budget", "task_order", "metric"], sort=True):
            cells = []
            for sees in ("image", "views"):
                of = at[at["sees"] == sees]
                if of.empty:
                    cells += ["not run", "", ""]
                    continue
                best = of.sort_values("mean", ascending=metric in lower).iloc[0]
                diffs = of[of["method"] == best["method"]].set_index("vs")
                cells.append(f"`{best['method']}` {_num(best['mean'])} ({best['pool']})")
                others = [v for v in diffs.index.dropna() if v not in ("colmap-b", "")]
                own = best["method"] if best["role"] == "peer" else next(iter(others), "colmap-b")
                cells += [
                    "itself" if vs == best["method"] else _pooled_diff(diffs, vs)
                    for vs in ("colmap-b", own)  # own: its pool's top-B, as table_pools paired it
                ]
            out.append(
                f"| {label} | {budget} | {_task(vocab, metric)} ({metric}) | "
                + " | ".join(cells)
                + " |"
            )
            leaders.setdefault((budget, metric), {})[label] = cells[0].split(" ")[0]
    return out + ["", *_agreement(leaders, vocab), ""]


def _agreement(leaders: dict, vocab: Vocabulary) -> list[str]:
    """Where the snapshots share a budget and task: whether their `image` leaders are the
    same method."""
    said = []
    for (budget, metric), by in leaders.items():
        if len(by) < 2:
            continue
        task = _task(vocab, metric)
        names = set(by.values())
        said.append(
            f"in {task} at {budget} they agree on {names.pop()}"
            if len(names) == 1
            else f"in {task} at {budget} " + ", ".join(f"the {k} name {v}" for k, v in by.items())
        )
    return (
        ["Own-image leaders on renders and photographs: " + "; ".join(said) + "."] if said else []
    )


def _pooled_diff(diffs: pd.DataFrame, vs: str) -> str:
    """A leader's paired difference from `vs` (`diffs`: its rows by `vs`) with its
    interval and verdict, as the table writes it."""
    if vs not in diffs.index or not diffs.loc[vs, "n"] or pd.isna(diffs.loc[vs, "mean_diff"]):
        return "n/a"
    r = diffs.loc[vs]
    diff = f"{_num(r['mean_diff'], True)} [{_num(r['lo'], True)}, {_num(r['hi'], True)}]"
    return f"{diff} {r['verdict']}"


def _predicts(r) -> str:
    """The table's last column: how the renders predict the set against the other sets."""
    how = prediction(r)
    return how if how in (CANNOT_TELL, "n/a") else f"{how} the others"


def _transfer_rows(summary: pd.DataFrame, photos: Path, vocab: Vocabulary) -> list[str]:
    """Per set, metric and category at `HEADLINE_BUDGET`: the renders' Kendall tau against
    the set's ranking, the ceiling the two rankings' reliabilities allow, the other sets'
    tau, and whether the renders predict the set as well as they do
    (`bench.report.transfer.prediction`)."""
    rows = summary[summary["matched"] & (summary["budget"] == HEADLINE_BUDGET)]
    if rows.empty or "rel_rendered" not in rows:
        return ["", "- no set has a baseline."]
    out = [
        f"On the photographs ({photos.as_posix()}/README.md): Kendall's tau between the",
        f"renders' ranking of the methods at {HEADLINE_BUDGET} and each set's (1: the same order, "
        "0: no relation),",
        "with its 95 % interval over methods; the ceiling the two rankings' split-half",
        "reliabilities allow; the other sets' tau for this set (the real-to-real baseline); and",
        "whether the renders predict the set as well as the other sets do (their tau within",
        "the interval), less well or better:",
        "",
        "| set | task (metric) | sees | tau [95 %] | reliability renders / set | ceiling "
        "| other sets' tau | the renders predict it |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows.sort_values(
        ["dataset", "metric", "sees"], ascending=[True, False, False]
    ).itertuples():
        tau = (
            r.tau_note
            if math.isnan(r.kendall_tau)
            else f"{r.kendall_tau:.2f} [{r.tau_lo:.2f}, {r.tau_hi:.2f}]"
        )
        out.append(
            f"| {r.dataset} | {_task(vocab, r.metric)} ({r.metric}) | {r.sees} | {tau} | "
            f"{r.rel_rendered:.2f} / {r.rel_dataset:.2f} | {_num(r.ceiling, digits=2)} | "
            f"{_num(r.tau_photos, digits=2)} | {_predicts(r)} |"
        )
    return out + [""]


NBV_CHOOSER = "weak-triangulation"
"""The paper's next-view chooser, whose gains the README states (`_nbv_rows`)."""


def _nbv_rows(table3: pd.DataFrame, nbv: Path) -> list[str]:
    """The next-views snapshot's pooled paired differences: `NBV_CHOOSER` minus each
    baseline chooser, per score and number of added views k (Table 3's `all scenes`)."""
    pooled = table3[(table3["scene"] == POOLED) & (table3["method"] == NBV_CHOOSER)]
    if pooled.empty:
        return []
    paths = int(pooled["n"].max())
    out = [
        f"Next views ({nbv.as_posix()}/README.md, Table 3): `{NBV_CHOOSER}` minus each",
        f"baseline chooser after k added views, paired over the {paths} rendered paths at "
        f"{int(pooled['budget'].iloc[0])}",
        "keypoints per view (95 % interval; paths won/tied/lost); `completeness`: the tri",
        "task's completeness, in percentage points; `maa`: the sfm task's pose mAA:",
        "",
        "| score | k | "
        + " | ".join(f"- `{b}`" for b in sorted(pooled["baseline"].unique()))
        + " |",
        "|---|---|" + "---|" * pooled["baseline"].nunique(),
    ]
    for (score, k), g in pooled.groupby(["score", "k"], sort=True):
        cells = [
            f"{_num(r.diff, True)} [{_num(r.diff_lo, True)}, {_num(r.diff_hi, True)}] "
            f"{r.wins}/{r.ties}/{r.losses}"
            for r in g.sort_values("baseline").itertuples()
        ]
        out.append(f"| {score} | {k} | " + " | ".join(cells) + " |")
    return out + [""]


def with_section(readme: str, section: str) -> str:
    """`readme` with the text between its markers replaced by `section`."""
    if (
        readme.count(BEGIN) != 1
        or readme.count(END) != 1
        or readme.index(BEGIN) > readme.index(END)
    ):
        raise BenchError(f"README.md lacks its results markers ({BEGIN} ... {END})")
    head, rest = readme.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{section}{END}{tail}"


def section_of(readme: str) -> str:
    """The text between a README's markers."""
    return readme.split(BEGIN)[1].split(END)[0].lstrip("\n")
