"""The results page (`README.md` of a results folder): written from the folder's files alone."""

from __future__ import annotations

import itertools
import math
import shutil
from pathlib import Path

import pandas as pd
import pytest

from bench.binding import read_vocabulary
from bench.report.page import results_page
from bench.report.tables import with_shares
from bench.report.write import write_tables
from bench.results import PAGE
from bench.runs import read_runs
from bench.vocabulary import Vocabulary

PUBLISHED = Path(__file__).resolve().parents[1] / "results" / "published"


@pytest.mark.parametrize("regime", ["published", "published-dense", "published-nbv"])
def test_the_published_page_is_what_its_runs_csv_gives(tmp_path, regime):
    """Every table of each published snapshot (both regimes, the next views) computed again
    from its runs.csv alone gives its page, word for word: no number on it is typed by hand
    or left from older rows."""
    snapshot, folder = PUBLISHED.with_name(regime), tmp_path / regime
    shutil.copytree(snapshot, folder, ignore=shutil.ignore_patterns("*.csv", PAGE))
    shutil.copyfile(snapshot / "runs.csv", folder / "runs.csv")
    vocab = read_vocabulary(folder)
    df = with_shares(read_runs(folder / "runs.csv"), vocab)
    write_tables(df, folder, vocab)
    assert results_page(folder) == (snapshot / PAGE).read_text()


def test_the_page_shows_each_interval_and_no_interval_where_a_table_has_none(tmp_path):
    shutil.copyfile(PUBLISHED / "vocabulary.json", tmp_path / "vocabulary.json")
    runs = pd.read_csv(PUBLISHED / "runs.csv", nrows=3)
    runs.to_csv(tmp_path / "runs.csv", index=False)
    pd.DataFrame(
        {
            "strategy": ["Texture-only", "Random budget"],
            "method": ["texture", "random"],
            "budget": [256, 256],
            "runs": [5, 1],
            "rmse": [0.5, 0.125],
            "rmse_lo": [0.25, None],
            "rmse_hi": [0.75, None],
        }
    ).to_csv(tmp_path / "table1.csv", index=False)
    page = results_page(tmp_path)
    assert "| texture | 256 | 5 | 0.50 [0.25, 0.75] |" in page  # the key, as --methods takes
    assert "| random | 256 | 1 | 0.12 |" in page  # one run: the mean alone; one format a column
    assert "Texture-only" not in page
    assert "figure3.png" not in page  # no figure drawn, none shown


@pytest.fixture(scope="module")
def every_task(quick_results, tmp_path_factory):
    """A tiny grid of every task under both protocols, as `bench run` ran it: the small
    grid's rows of one scene and three methods (whole rows: their checksums hold), with its
    models, manifest and settings."""
    results = tmp_path_factory.mktemp("every-task") / "r"
    ignore = shutil.ignore_patterns("*.csv", "*.png", "*.pdf", PAGE)
    shutil.copytree(quick_results, results, ignore=ignore)
    runs = pd.read_csv(quick_results / "runs.csv", dtype=str, keep_default_na=False)
    keep = (runs["scene"] == "facade") & runs["method"].isin(["texture", "adaptive", "colmap"])
    runs[keep].to_csv(results / "runs.csv", index=False)
    return results


def test_the_page_bench_run_writes_is_complete(quick_results):
    page = (quick_results / PAGE).read_text()
    run = page.split("## The run")[1].split("## Grid")[0]  # the headline above says n/a (1 seed)
    assert "n/a" not in run, run  # the run's commit, variant, machine and versions
    assert "Seconds per stage" in run and "runs_wall" in run
    assert "Wall seconds per phase" in run and "| workers | cores |" in run


TASKS, PROTOCOLS = ("tri", "sfm", "pairs"), ("multiview", "twoview")
SUBSETS = [
    (tasks, protocols)
    for n in (1, 2, 3)
    for tasks in itertools.combinations(TASKS, n)
    for protocols in (("multiview",), ("twoview",), PROTOCOLS)
]


@pytest.mark.parametrize("tasks, protocols", SUBSETS, ids=lambda x: "+".join(x))
def test_every_task_and_protocol_subset_writes_its_tables_figures_and_page(
    every_task, tmp_path, tasks, protocols
):
    """A grid of any non-empty set of tasks and protocols (the rows of a larger one) gets
    its Table 1, its figures and its page from `bench plot`."""
    from bench.cli import main

    folder = tmp_path / "r"
    shutil.copytree(every_task, folder, ignore=shutil.ignore_patterns("*.csv", "*.png", PAGE))
    runs = pd.read_csv(every_task / "runs.csv", dtype=str, keep_default_na=False)
    keep = runs["task"].isin(tasks) & runs["protocol"].isin([*protocols, "none"])  # pairs: none
    runs[keep].to_csv(folder / "runs.csv", index=False)  # whole rows: their checksums hold
    assert main(["plot", "--results", str(folder)]) == 0
    tracked = [t for t in tasks if t != "pairs"]
    table = "table1.csv" if "multiview" in protocols or not tracked else "table1_twoview.csv"
    # a pairs-only run has one protocol, none, and no twoview table
    assert (folder / "table1_twoview.csv").is_file() == bool("twoview" in protocols and tracked)
    t1 = pd.read_csv(folder / table)
    for task in tasks:
        assert any(c == "acc_completeness_pct" or c.startswith(f"{task}_") for c in t1) or (
            task == "tri"
        )
    assert (folder / "figure3.png").is_file() and (folder / PAGE).is_file()


def test_a_task_table_counts_its_own_runs_and_gives_its_own_columns_reasons():
    """The sfm table's runs leave out the cells the exclusion rule leaves out, and say how
    many could not be computed; the reasons for a missing interval are those of the
    columns shown (published sparse page, texture at 256: 'n/a (no spread); n/a (1 seed)'
    came from columns the tri table does not show)."""
    from bench.report.page import _runs, _why

    vocab = Vocabulary.current()
    row = pd.Series({"runs": 20, "sfm_excluded_runs": 5, "sfm_error_runs": 2, "error_runs": 0.0})
    assert _runs(row, vocab, "sfm") == "15 (2 could not be computed)"
    assert _runs(row, vocab, "tri") == "20"
    note = "n/a (no spread): runtime_matching, pairs_task_ms; n/a (1 seed): acc_completeness_pct"
    assert _why(note, ["acc_completeness_pct", "accuracy_pct", "rmse"]) == "n/a (1 seed)"
    assert _why(note, ["sfm_maa"]) == ""


def test_bench_runs_table1_names_keys_and_counts_runs_as_the_page_does():
    """The printed Table 1 was about 330 characters wide, named display labels and counted
    every unit in `runs` where the page's sfm table leaves out the excluded cells."""
    from bench.report.page import brief_table1

    t1 = pd.read_csv(PUBLISHED / "table1.csv")
    vocab = read_vocabulary(PUBLISHED)
    lines = brief_table1(t1, vocab).splitlines()
    assert max(map(len, lines)) <= 120
    header = lines[0].split()
    assert header[:2] == ["method", "budget"] and "sfm_runs" in header and "sfm_maa" in header
    page = (PUBLISHED / PAGE).read_text()
    sfm = page[page.index("### `sfm`") : page.index("### `pairs`")]
    for line in lines[1:]:
        cells = dict(zip(header, line.split()))
        if cells["budget"] == "256":
            assert f"| {cells['method']} | 256 | {cells['sfm_runs']} | " in sfm, cells


def test_table2_counts_the_runs_of_each_column(tmp_path):
    """Table 2 compared adaptive over 4 runs with random over 3 beside a difference paired
    over 3, and did not say so; the counts are now in table2.csv and on the page."""
    from bench.report.tables import headline_frame, paired, table2

    rows = []
    for seed in range(4):
        cell = dict(scene="s", seed=seed, budget=64, task="tri", protocol="multiview")
        for method, rmse in (("texture", 0.2), ("adaptive", 0.1)):
            value = math.nan if (method, seed) == ("texture", 3) else rmse
            rows.append(cell | dict(method=method, rmse=value, status="ok"))
    vocab = Vocabulary.current()
    frame = headline_frame(pd.DataFrame(rows), vocab)
    t2 = table2(frame, paired(frame, vocab), vocab).set_index("scene").loc["all scenes"]
    assert (t2["adaptive_rmse_n"], t2["best_baseline_rmse_n"], t2["diff_rmse_n"]) == (4, 3, 3)


def test_a_dataset_pages_transfer_section_reads_as_its_csv_and_leaves_out_what_did_not_run(
    tmp_path,
):
    """`matched` read 1/0 on the page and True/False in the CSV, `tau_note` n/a and empty;
    Table 2 and "Paired: adaptive ..." were printed full of "n/a (no run)" when adaptive did
    not run; "render variant: []"; nothing said what the columns or the oracle are."""
    import json

    shutil.copyfile(PUBLISHED / "vocabulary.json", tmp_path / "vocabulary.json")
    pd.read_csv(PUBLISHED / "runs.csv", nrows=3).to_csv(tmp_path / "runs.csv", index=False)
    (tmp_path / "manifest.json").write_text(json.dumps({"variant": []}))
    t1 = {"method": ["texture", "grid", "oracle"], "budget": [256] * 3, "runs": [10] * 3}
    pd.DataFrame(t1).to_csv(tmp_path / "table1.csv", index=False)
    pd.DataFrame({"scene": ["all"], "budget": [256], "adaptive_rmse": [None]}).to_csv(
        tmp_path / "table2.csv", index=False
    )
    row = dict(dataset="d", rendered_views=6, matched=True, metric="sfm_maa", budget=256)
    row |= dict(methods=3, kendall_tau=math.nan, tau_lo=math.nan, tau_hi=math.nan, tau_note="")
    row |= dict(rel_rendered=0.9, rel_dataset=0.8, ceiling=0.85, tau_photos=math.nan)
    row |= dict(biggest_movers="texture rendered 2 -> set 1")
    pd.DataFrame([row]).to_csv(tmp_path / "transfer.csv", index=False)
    page = results_page(tmp_path)
    section = page.split("## Transfer")[1]
    assert "| d | 6 | True | sfm_maa | 256 | 3 | n/a | n/a | n/a |  | 0.90 |" in section
    assert "- d, sfm_maa, B = 256, against the 6-view renders: no tau; the split-half" in section
    assert "`rel_rendered` and `rel_dataset` the split-half reliability" in section
    assert "## Table 2" not in page and "Paired: adaptive" not in page
    assert "render variant: none (nothing rendered)" in page
    assert "`oracle` is a reference selection made with the ground truth" in page
    assert "it is not a bound" in page


def test_a_columns_numbers_share_one_format_that_tells_them_apart():
    """Three significant figures mixed 0.03, 0.0333 and 0.243 in one column and printed
    0.9995 as "1"."""
    from bench.report.text import ci, column_format

    fmt = column_format([0.03, 0.0333, 0.243, 0.9995])
    assert [fmt(v) for v in (0.03, 0.0333, 0.243, 0.9995)] == [
        "0.0300",
        "0.0333",
        "0.2430",
        "0.9995",
    ]
    fmt = column_format([0.25, 0.5], [0.1, 0.75])
    assert ci(0.5, 0.1, 0.75, fmt=fmt) == "0.50 [0.10, 0.75]" and fmt(math.nan) == "n/a"
    assert column_format([3, 12, 20])(12) == "12"  # whole numbers stay whole


def test_a_difference_reads_with_its_sign_in_the_columns_format():
    """The page's difference columns printed 0.0761 beside -0.0717: a gain read as a level."""
    from bench.report.text import ci, column_format, signed

    fmt = signed(column_format([-0.0717, 0.0761], [-0.219, 0.0761]))
    assert ci(-0.0717, -0.219, 0.0761, fmt=fmt) == "-0.07 [-0.22, +0.08]"
    assert fmt(0.0) == "0.00" and fmt(math.nan) == "n/a"
