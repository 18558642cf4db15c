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
    "is refused), from the reference renders, then compare each metric column of each row "
    "with the published row. It names the snapshot (its origin.json: version, commit, "
    "reference renders) and the modules whose code differs since, then prints one of three "
    "classes: 'identical'; 'equal but for floating-point last bits' (the continuous "
    "measures bundle adjustment refines, within a relative 1e-7, named with their columns); "
    "or what moved (column, how many values, by how much). It exits 1 when a value moved, "
    "when the rows read other pixels or when a published row has no counterpart, and with "
    "--exact also when only last bits differ. The slice's rows name the pixels they read, "
    "so a published row is only ever compared with a row of the same images."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    regime_arg(parser, "the snapshot to reproduce")
    parser.add_argument(
        "--published", type=folder, default=None, help="a snapshot folder (default: the regime's)"
    )
    parser.add_argument("--scenes", default="facade", help="scenes of the slice (default: facade)")
    parser.add_argument("--seeds", default="0", help="seeds of the slice (default: 0)")
    parser.add_argument(
        "--budget", type=int, default=256, help="a budget of the snapshot (default: 256)"
    )
    parser.add_argument(
        "--if-changed",
        action="store_true",
        help="compute nothing where the code is the snapshot's (every module's hash the same, "
        "its origin.json says): what CI runs after the tests",
    )
    parser.add_argument(
        "--exact",
        action="store_true",
        help="exit 1 also where values differ only in their floating-point last bits",
    )
    parser.add_argument(
        "--results",
        type=Path,
        default=None,
        help="where the slice is computed (default: results/reproduce-<regime>)",
    )
    parser.add_argument("--workers", type=int, default=None, help="as `bench run --workers`")
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.harness.origin import changed_modules, header, read_origin
    from bench.results import ORIGIN, RUNS
    from bench.runs import read_runs

    regime = args.regime or "sparse"
    published = args.published or ROOT / regime_folder(PUBLISHED, regime)
    scenes = parse_list("--scenes", args.scenes, str, "facade")
    seeds = parse_list("--seeds", args.seeds, int, "0")
    if args.workers is not None and args.workers < 1:
        raise BenchError(f"--workers must be at least 1, got {args.workers}")
    rows = read_runs(published / RUNS)
    budgets = sorted(int(b) for b in set(rows["budget"]) - {0})
    if args.budget not in budgets:
        raise BenchError(
            f"--budget {args.budget}: {published} holds budgets {', '.join(map(str, budgets))}"
        )
    mine = rows["scene"].isin(scenes) & rows["seed"].isin(seeds)
    want = rows[mine & rows["budget"].isin((args.budget, 0))]
    if want.empty:
        raise BenchError(
            f"{published} holds no rows of scenes {','.join(scenes)}, seeds "
            f"{','.join(map(str, seeds))} at budget {args.budget}"
        )
    if (published / ORIGIN).is_file() or args.if_changed:
        origin = read_origin(published)
        changed = changed_modules(origin)
        print(f"{published}: {header(origin)}")
        print(
            f"the code differs from the snapshot's in {len(changed)} module(s): "
            + ", ".join(changed)
            if changed
            else "the code is the snapshot's (every module's hash the same)"
        )
        if args.if_changed and not changed:
            return
    out = args.results or Path(f"results/reproduce-{regime}")
    result = reproduce_slice(published, want, out, args.renders, args.workers)
    print(f"{published} against {out}:")
    print("\n".join(result.lines()))
    if result.moved or result.pixels or result.common < len(want):
        raise SystemExit(1)
    if args.exact and result.last_bits:
        raise SystemExit(1)


def reproduce_slice(published: Path, want, out: Path, renders: Path, workers: int | None):
    """`want` (rows of the snapshot in `published`) computed into `out` under the
    snapshot's settings, from the reference renders, and compared with them
    (`bench.report.compare.Comparison`)."""
    from bench.binding import read_settings
    from bench.cli import build_parser
    from bench.report.compare import compare_rows
    from bench.results import CONFIG, RUNS
    from bench.runs import read_runs

    if read_settings(published)["render"] is None:
        raise BenchError(f"{published} is a dataset run: `bench reproduce` takes a rendered one")
    if not (out / CONFIG).is_file():  # the snapshot's settings bind the folder
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy2(published / CONFIG, out / CONFIG)
    argv = ["run", "--results", str(out), "--renders", str(renders)]
    argv += ["--methods", ",".join(sorted(set(want["method"]))), *snapshot_grid(published, want)]
    argv += ["--frontier", "none", *(["--workers", str(workers)] if workers else [])]
    print("bench " + " ".join(argv))
    sub = build_parser(only="run").parse_args(argv)
    sub.func(sub)
    return compare_rows(want, read_runs(out / RUNS))
