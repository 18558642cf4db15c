"""`bench publish`: a checked results folder into the snapshot the repository tracks."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.cli.common import LATEST, PUBLISHED, results_arg

HELP = "copy a results folder's runs, tables and figures into the published snapshot"
DESCRIPTION = (
    "Check RESULTS/runs.csv row by row, then copy it with config.json, vocabulary.json, "
    "manifest.json, the tables and the figures into TO (the snapshot the repository "
    "tracks), removing report files there that RESULTS does not have."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    results_arg(parser, LATEST, f"results folder to publish (default: ./{LATEST})")
    parser.add_argument(
        "--to", type=Path, default=PUBLISHED, help=f"snapshot folder (default: ./{PUBLISHED})"
    )


def run(args: argparse.Namespace) -> None:
    from bench.report.write import publish

    print(f"published {publish(args.results, args.to)} files of {args.results} in {args.to}")
