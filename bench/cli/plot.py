"""`bench plot`: the tables and figures again, from a results folder alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench import ROOT
from bench.cli.common import (
    LATEST,
    PUBLISHED,
    published_snapshots,
    regime_folder,
    renders_arg,
    results_arg,
)

HELP = "rebuild the tables and figures from runs.csv (no rendering, no reconstruction)"
DESCRIPTION = (
    "Rewrite table1.csv, table1_twoview.csv, table2.csv, paired.csv, paired_sfm.csv, "
    "table_scenes.csv, frontend_cost.csv, verdicts.csv, table_cost.csv, table_pools.csv (rows on several pools), figure_cost.png, "
    "figure3.png/.pdf, figure_budget.png (where the grid has several budgets), and the "
    "results page README.md from "
    "RESULTS/runs.csv and RESULTS/vocabulary.json alone, and figure2.png from them plus an "
    "exported model and its cached render. A results folder of datasets also gets "
    "transfer.csv, transfer_ranks.csv and figure_transfer.png (its ranking against a rendered "
    "results folder's) and, with several datasets, table1-<dataset>.csv."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    results_arg(parser, LATEST, f"results folder (default: ./{LATEST})")
    renders_arg(parser)
    parser.add_argument(
        "--rendered",
        type=Path,
        action="append",
        default=None,
        metavar="DIR",
        help="for a results folder of datasets: a rendered results folder whose ranking "
        "transfer.csv compares with theirs (repeatable; default: the package's snapshot of "
        f"each regime, {ROOT / PUBLISHED} and {ROOT / regime_folder(PUBLISHED, 'dense')})",
    )


def run(args: argparse.Namespace) -> None:
    from bench.report.write import write_report
    from bench.results import RUNS, holding
    from bench.runs import read_runs, runs_file

    runs_csv = runs_file(args.results / RUNS)
    with holding(args.results):  # refused while a run writes the folder
        write_report(
            read_runs(runs_csv),
            args.results,
            args.renders,
            args.rendered or published_snapshots(),
        )
    print(f"tables and figures rewritten in {args.results}")
