"""The report: tables and figures from `runs.csv` and the vocabulary recorded beside it
(Figure 2 also reads an exported model and its render). Nothing here renders, selects or
reconstructs, and nothing here imports the stages that do.

Written files: `table1.csv` (headline task and protocol), `table1_twoview.csv` (where
rows ran under that protocol),
`table2.csv`, `paired.csv`, `paired_sfm.csv`, `table_scenes.csv`, `frontend_cost.csv`,
`table1_equal.csv` where equal-count methods ran with their peer (`bench.report.tables`),
`verdicts.csv`, each category of `sees` against its peer (`bench.report.categories`),
`table_cost.csv` and `figure_cost.png`, quality against cost (`bench.report.cost`), `figure3.png/.pdf`, `figure_budget.png` (with several budgets)
and `figure2.png` (`bench.report.figures`), `table3.csv` and `figure_views.png` with rows
of the next-views task (`bench.report.nbv`), and last the folder's page, `README.md`
(`bench.report.page`). A results folder of datasets also gets
`table1-<dataset>.csv` per dataset when it holds several, and `transfer.csv`,
`transfer_ranks.csv` and `figure_transfer.png` against rendered results folders
(`bench.report.transfer`). A table or figure that cannot be drawn from these rows is
removed, never left stale.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.binding import read_settings, read_vocabulary
from bench.console import log
from bench.failures import exclusions, failures
from bench.files import write_text_atomic
from bench.report.categories import category_verdicts, unjudged
from bench.report.cost import figure_cost, frontier_only, table_cost
from bench.report.figures import (
    figure2,
    figure2_expected,
    figure3,
    figure_budget,
    figure_transfer,
    headline_budget,
)
from bench.report.nbv import figure_views, table3
from bench.report.page import results_page
from bench.report.pools import table_pools
from bench.report.tables import (
    equal_keypoints,
    frontend_cost,
    headline_frame,
    paired,
    paired_sfm,
    rule_column,
    table1,
    table2,
    table_scenes,
    with_shares,
)
from bench.report.transfer import said as transfer_said
from bench.report.transfer import transfer_regimes, verdicts, why_none
from bench.results import (
    FIGURE2,
    FIGURE3,
    FIGURE_BUDGET,
    FIGURE_COST,
    FIGURE_TRANSFER,
    FIGURE_VIEWS,
    FRONTEND_COST,
    PAGE,
    PAIRED,
    PAIRED_SFM,
    RUNS,
    TABLE1,
    TABLE1_EQUAL,
    TABLE1_TWOVIEW,
    TABLE2,
    TABLE3,
    TABLE_COST,
    TABLE_POOLS,
    TABLE_SCENES,
    TRANSFER,
    TRANSFER_RANKS,
    VERDICTS,
    png,
    table1_of,
)
from bench.vocabulary import BAG, HEADLINE, PROTOCOLS, Vocabulary


def _drop(*paths: Path) -> None:
    for p in paths:
        p.unlink(missing_ok=True)


def _settings(results: Path) -> dict:
    """The settings of `results` (`config.json`), or none (a folder of tables alone)."""
    try:
        return read_settings(results)
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def is_dataset_run(results: Path) -> bool:
    """Whether `results` holds runs on datasets (its settings render nothing)."""
    try:
        return read_settings(results)["render"] is None
    except (OSError, ValueError, KeyError, TypeError):
        return False


def write_report(
    df: pd.DataFrame, results: Path, renders: Path, rendered: Sequence[Path] = ()
) -> pd.DataFrame | None:
    """Every table and figure of `results` from the rows `df`, under the vocabulary
    recorded in `results`; for a results folder of datasets, the transfer tables against
    the rendered results folders `rendered`; last, the folder's page. Returns the Table 1
    the figures draw (the headline protocol's, else the first with rows), or None."""
    results = Path(results)
    check_one_bag_size(df)
    vocab = read_vocabulary(results)
    df = with_shares(df, vocab)
    everything, df = df, df[~frontier_only(df)]  # the frontiers' rows: the cost's alone
    tables = write_tables(everything, results, vocab)
    if is_dataset_run(results):
        _write_transfer(df, vocab, results, rendered)
    drawn = next((t for t in tables if not t.empty), None)  # the headline protocol first
    if drawn is None:
        _drop(results / png(FIGURE3), results / f"{FIGURE3}.pdf", results / png(FIGURE_BUDGET))
        log("no run under any track protocol: no Table 1 and no figures")
    else:
        _write_figures(df, drawn, results, Path(renders))
    if not figure_views(df, vocab, results / FIGURE_VIEWS):
        _drop(results / png(FIGURE_VIEWS))
    write_text_atomic(results / PAGE, results_page(results, everything))
    return drawn


def check_one_bag_size(df: pd.DataFrame) -> None:
    """Refuse rows of one dataset in bags of several sizes (a folder keeps every bag
    setting's rows, `KEY`): bag k of each size is a seed k of its own, so the tables would
    pair bags of different sizes. `bench run` hands its page its own bags alone."""
    if BAG not in df or not (df[BAG] != "").any():
        return
    sizes = df[df["views"].notna()].groupby("scene")["views"].unique()
    several = sizes[sizes.map(len) > 1]
    if len(several):
        scene, views = several.index[0], sorted(int(v) for v in several.iloc[0])
        raise BenchError(
            f"{scene} has rows of bags of {' and '.join(map(str, views))} views: a page is of one "
            "bag size; run the `bench run --dataset ... --bag-size N` of the bags you want (it "
            "reuses every row and writes their page)"
        )


def write_tables(df: pd.DataFrame, results: Path, vocab: Vocabulary) -> list[pd.DataFrame]:
    """Every table of `results` from the rows `df` (with the report's shares; the frontiers'
    rows, `bench.report.cost.frontier_only`, in the cost's alone); Table 1 of each track
    protocol rows ran under (the rows of a task without tracks in each, or in the
    headline's alone), the headline's first (what the figures draw: the first with rows)."""
    costed, df = df, df[~frontier_only(df)]
    datasets = is_dataset_run(results)
    frame = headline_frame(df, vocab, dataset=datasets)
    t1, pairs = table1(frame, vocab), paired(frame, vocab)
    for task in (t for t in vocab.exclusion_tasks if rule_column(vocab, t) in frame and len(frame)):
        rule = frame[rule_column(vocab, task)].iloc[0]
        log(f"{task} exclusion rule (cells stock COLMAP does not map): {rule}")
    if datasets:
        _write_tables(results, _per_dataset(frame, vocab, results))
    ran = set(df["protocol"]) & set(PROTOCOLS)  # a task without tracks joins each, or is alone
    tables = {
        TABLE1: t1 if HEADLINE[1] in ran or not ran else pd.DataFrame(),
        TABLE1_TWOVIEW: table1(headline_frame(df, vocab, "twoview", datasets), vocab)
        if "twoview" in ran
        else pd.DataFrame(),
        TABLE2: table2(frame, pairs, vocab),
        PAIRED: pairs,
        PAIRED_SFM: paired_sfm(frame, vocab),
        TABLE_SCENES: table_scenes(frame, vocab) if len(frame) else pd.DataFrame(),
        FRONTEND_COST: frontend_cost(df, vocab),
        TABLE3: table3(df, vocab),
        TABLE1_EQUAL: equal_keypoints(frame, vocab),
        VERDICTS: category_verdicts(frame, vocab) if len(frame) else pd.DataFrame(),
        TABLE_POOLS: table_pools(frame, vocab, df),
        TABLE_COST: table_cost(
            costed, headline_frame(costed, vocab, dataset=datasets), vocab, _settings(results)
        ),
    }
    _write_tables(results, tables)
    for line in unjudged(vocab, set(df["method"])):
        log(line)
    return [tables[TABLE1], tables[TABLE1_TWOVIEW]]


def _write_figures(df: pd.DataFrame, t1: pd.DataFrame, results: Path, renders: Path) -> None:
    vocab = read_vocabulary(results)
    note = figure3_note(df, vocab, is_dataset_run(results))
    figure3(t1, vocab, results / FIGURE3, note=note)
    if (t1["budget"] > 0).sum() and t1.loc[t1["budget"] > 0, "budget"].nunique() > 1:
        figure_budget(t1, vocab, results / FIGURE_BUDGET)
    else:
        _drop(results / png(FIGURE_BUDGET))
    cost = results / TABLE_COST
    if not cost.is_file() or not figure_cost(pd.read_csv(cost), vocab, results / FIGURE_COST):
        _drop(results / png(FIGURE_COST))
    why = figure2(df, results, renders, results / FIGURE2)
    if why and (figure2_expected(df) or (results / png(FIGURE2)).exists()):
        log(f"{png(FIGURE2)} not drawn (and any older one removed): {why}")
    if why:
        _drop(results / png(FIGURE2))


def figure3_note(df: pd.DataFrame, vocab: Vocabulary, dataset: bool = False) -> str:
    """Figure 3's note: the rows that failed, and the cells the sfm means leave out."""
    said = [s for s in (failures(df), exclusions(df, vocab, dataset)) if s]
    return f"Of {len(df)} rows: " + "\n".join(said) if said else ""


def _write_tables(results: Path, tables: dict[str, pd.DataFrame]) -> None:
    for name, t in tables.items():
        if t.empty:
            _drop(results / name)
        else:
            write_text_atomic(results / name, t.to_csv(index=False, float_format="%.6g"))


def _per_dataset(frame: pd.DataFrame, vocab: Vocabulary, results: Path) -> dict:
    """`table1-<dataset>.csv` per dataset when there are several (the old ones dropped)."""
    scenes = list(dict.fromkeys(frame["scene"]))
    tables = {p.name: pd.DataFrame() for p in results.glob(table1_of("*"))}
    if len(scenes) > 1:
        tables |= {table1_of(s): table1(frame[frame["scene"] == s], vocab) for s in scenes}
    return tables


def _write_transfer(df: pd.DataFrame, vocab: Vocabulary, results: Path, rendered: Sequence[Path]):
    """transfer.csv, transfer_ranks.csv and figure_transfer.png (the matched regime's), or
    why not (logged)."""
    names = (TRANSFER, TRANSFER_RANKS)
    missing = [Path(r) / RUNS for r in rendered if not (Path(r) / RUNS).is_file()]
    if not rendered or missing:
        _drop(*(results / n for n in (*names, png(FIGURE_TRANSFER))))
        where = "; ".join(f"{m} is missing" for m in missing) or "none given"
        log(
            f"no transfer.csv: no rendered results to compare with ({where}; give a rendered "
            "results folder with --rendered DIR)"
        )
        return
    summary, ranks = transfer_regimes(df, vocab, rendered)
    _write_tables(results, dict(zip(names, (summary, ranks))))
    if summary.empty:
        _drop(results / png(FIGURE_TRANSFER))
        log(
            f"no transfer.csv: the datasets and the rendered results share {why_none(df, rendered)}"
        )
        return
    budget = headline_budget(summary)
    matched = summary["matched"], ranks["matched"]
    figure_transfer(ranks[matched[1]], summary[matched[0]], budget, results / FIGURE_TRANSFER)
    for line in transfer_said(summary, budget) + verdicts(summary, budget):
        log(f"{results / TRANSFER}: {line}")
