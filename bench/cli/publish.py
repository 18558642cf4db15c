"""`bench publish`: a checked results folder into the snapshot the repository tracks."""

from __future__ import annotations

import argparse

from bench.cli.common import (
    LATEST,
    PUBLISHED,
    folder,
    regime_arg,
    regime_folder,
    results_arg,
)

HELP = "copy a results folder's runs, tables and figures into the published snapshot"
DESCRIPTION = (
    "Check RESULTS/runs.csv row by row, then copy it with config.json, vocabulary.json, "
    "manifest.json, the tables and the figures into TO (the snapshot the repository "
    "tracks), removing report files there that RESULTS does not have. A snapshot of other "
    "settings (config.json) or another grid (scenes, seeds, methods, budgets, tasks, "
    "protocols) is replaced only with --replace."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    dense = regime_folder(LATEST, "dense"), regime_folder(PUBLISHED, "dense")
    results_arg(parser, None, f"results folder to publish (default: ./{LATEST}, or ./{dense[0]})")
    parser.add_argument(
        "--to",
        type=folder,
        default=None,
        help=f"snapshot folder (default: ./{PUBLISHED}, or ./{dense[1]})",
    )
    regime_arg(parser, "sets the default --results and --to")
    parser.add_argument(
        "--replace",
        action="store_true",
        help="replace a snapshot of other settings or another grid (refused without it)",
    )


def _defaults() -> dict:
    """The settings' defaults (imports OpenCV and COLMAP: only where a setting is missing)."""
    from bench.harness.config import RunConfig

    return RunConfig().as_dict()


def run(args: argparse.Namespace) -> None:
    from bench import BenchError
    from bench.report.write import publish
    from bench.results import holding, runs_file, snapshot_differences

    regime = args.regime or "sparse"
    args.results = args.results or regime_folder(LATEST, regime)
    args.to = args.to or regime_folder(PUBLISHED, regime)
    runs_file(args.results / "runs.csv")
    try:
        args.to.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(f"cannot write to {args.to}: {e.strerror}") from None
    with holding(args.results, reading=True), holding(args.to):
        differ = [] if args.replace else snapshot_differences(args.results, args.to, _defaults)
        if differ:
            raise BenchError(
                f"{args.to} holds a snapshot of other settings or another grid "
                f"({'; '.join(differ)}); --replace replaces it"
            )
        n = publish(args.results, args.to)
    print(f"published {n} files of {args.results} in {args.to}")
