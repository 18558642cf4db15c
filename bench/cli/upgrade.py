"""`bench upgrade`: a results folder written by an older bench, brought up to date."""

from __future__ import annotations

import argparse

from bench.cli.common import LATEST, results_arg

HELP = "bring a results folder written by an older bench up to date, in place"
DESCRIPTION = (
    "Rename runs.csv's `policy` column `method` (each row's checksum recomputed where it "
    "held), and record in RESULTS/vocabulary.json what the report reads of each task (its headline "
    "metrics, which are lower-better, its summary metrics, its figure titles, whether the "
    "stock-COLMAP exclusion rule holds), as this bench declares them. No row is computed "
    "again; run `bench plot` afterwards to rewrite the tables."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    results_arg(parser, LATEST, f"results folder (default: ./{LATEST})")


def run(args: argparse.Namespace) -> None:
    import bench.harness.tasks  # noqa: F401  (declares the tasks)
    from bench.results import holding, upgrade
    from bench.vocabulary import Vocabulary

    with holding(args.results):
        changed = upgrade(args.results, Vocabulary.current())
    print(
        "\n".join(f"{args.results}: {c}" for c in changed)
        or f"{args.results} is up to date; nothing changed"
    )
