"""`bench reproduce`: a slice of a published snapshot computed on this machine, from the
reference renders, and every metric column compared with the published rows."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from bench import ROOT, BenchError
from bench.cli.common import (
    PUBLISHED,
    folder,
    parse_list,
    regime_arg,
    regime_folder,
    renders_arg,
    snapshot_grid,
)

HELP = "compute a slice of a published snapshot here and compare every metric column"
DESCRIPTION = (
    "Run every method of the published snapshot of --regime (or --published DIR) on a slice "
    "of its grid (--scenes, --seeds, --budget; budget-0 methods such as colmap come along) "
    "into --results, under the snapshot's own settings (its config.json: a run under others "
    "is refused), from the reference renders, then compare each metric column of each row with the published row "
    "exactly: it prints 'identical' or what moved (column, how many values, by how much), "
    "and exits 1 when something moved. The slice's rows name the pixels they read, so a "
    "published row is only ever compared with a row of the same images."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    regime_arg(parser, "the snapshot to reproduce")
    parser.add_argument(
        "--published", type=folder, default=None, help="a snapshot folder (default: the regime's)"
    )
    parser.add_argument("--scenes", default="facade", help="scenes of the slice (default: facade)")
    parser.add_argument("--seeds", default="0", help="seeds of the slice (default: 0)")
    parser.add_argument("--budget", type=int, default=256, help="the budget (default: 256)")
    parser.add_argument(
        "--results",
        type=Path,
        default=None,
        help="where the slice is computed (default: results/reproduce-<regime>)",
    )
    parser.add_argument("--workers", type=int, default=None, help="as `bench run --workers`")
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.binding import read_settings
    from bench.cli import build_parser
    from bench.report.compare import compare_rows
    from bench.results import CONFIG, RUNS
    from bench.runs import read_runs

    regime = args.regime or "sparse"
    published = args.published or ROOT / regime_folder(PUBLISHED, regime)
    scenes = parse_list("--scenes", args.scenes, str, "facade")
    seeds = parse_list("--seeds", args.seeds, int, "0")
    rows = read_runs(published / RUNS)
    mine = rows["scene"].isin(scenes) & rows["seed"].isin(seeds)
    mine &= rows["budget"].isin((args.budget, 0))
    want = rows[mine]
    if want.empty:
        raise BenchError(
            f"{published} holds no rows of scenes {','.join(scenes)}, seeds "
            f"{','.join(map(str, seeds))} at budget {args.budget}"
        )
    out = args.results or Path(f"results/reproduce-{regime}")
    if not (out / CONFIG).is_file():  # the snapshot's settings bind the folder
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy2(published / CONFIG, out / CONFIG)
    if read_settings(published)["render"] is None:
        raise BenchError(f"{published} is a dataset run: `bench reproduce` takes a rendered one")
    argv = ["run", "--results", str(out), "--renders", str(args.renders)]
    argv += ["--methods", ",".join(sorted(set(want["method"]))), *snapshot_grid(published, want)]
    argv += ["--workers", str(args.workers)] if args.workers else []
    print("bench " + " ".join(argv))
    sub = build_parser(only="run").parse_args(argv)
    sub.func(sub)
    here = read_runs(out / RUNS)
    result = compare_rows(want, here)
    print(f"{published} against {out}:")
    print("\n".join(result.lines()))
    if result.moved or result.pixels or result.common < len(want):
        raise SystemExit(1)
