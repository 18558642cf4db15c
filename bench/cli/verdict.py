"""`bench verdict MODULE`: a policy module's rows computed beside the published snapshots,
and its verdict against the stock-COLMAP peer of its category."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from bench import ROOT, BenchError
from bench.cli.common import (
    PHOTOS,
    PUBLISHED,
    REGIMES,
    parse_list,
    regime_folder,
    renders_arg,
    snapshot_grid,
)

HELP = "your policy module's verdict against the published snapshots (its rows alone computed)"
DESCRIPTION = (
    "Copy the rows of each published snapshot (--regimes; with --dataset the photo sets' "
    "too) into --results/<snapshot>/ and compute there only the rows of MODULE's policies "
    "(every method it declares, or --methods), at the snapshot's budgets and tasks, from "
    "the reference renders; then print, for each snapshot, budget and headline metric, the "
    "policy against the stock-COLMAP peer of its category (`image`: colmap-b; `views`: "
    "colmap-tracks-b), paired over the snapshot's cells with a 95 %% interval. Its rows and "
    "the published ones read the same pixels (a mix is refused). A second call resumes; "
    "editing the module recomputes its rows alone."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("module", type=Path, metavar="MODULE", help="a policy module (.py)")
    parser.add_argument("--methods", default=None, help="its methods to run (default: all)")
    parser.add_argument(
        "--regimes", default=",".join(REGIMES), help="rendered snapshots (default: %(default)s)"
    )
    parser.add_argument(
        "--dataset",
        type=Path,
        action="append",
        default=[],
        help="the photo sets of results/published-datasets (a set, or a folder of sets; "
        "repeatable), scored in its bags",
    )
    parser.add_argument(
        "--results", type=Path, default=None, help="default: results/verdict-<module's name>"
    )
    parser.add_argument("--workers", type=int, default=None, help="as `bench run --workers`")
    renders_arg(parser)


def _snapshot_copy(snapshot: Path, out: Path) -> None:
    """The snapshot's rows and records into `out` (once: a second call resumes)."""
    from bench.results import CONFIG, MANIFEST, RUNS, VOCABULARY

    if (out / RUNS).is_file():
        return
    out.mkdir(parents=True, exist_ok=True)
    for name in (RUNS, CONFIG, VOCABULARY, MANIFEST):
        shutil.copy2(snapshot / name, out / name)


def run(args: argparse.Namespace) -> None:
    from bench.binding import read_vocabulary
    from bench.cli import build_parser
    from bench.frontend import plugins
    from bench.report.categories import category_verdicts, verdict_sentences
    from bench.report.tables import headline_frame
    from bench.results import RUNS
    from bench.runs import read_runs
    from bench.unit import declared  # noqa: F401 (every method of the package, first)

    module = args.module.resolve()
    if not module.is_file():
        raise BenchError(f"{args.module} is not a file (a policy module, .py)")
    plugins.load((str(module),))  # the package's methods imported first: not the module's
    new = sorted(m for m, origin in plugins.ORIGIN.items() if Path(origin) == module)
    methods = parse_list("--methods", args.methods, str) if args.methods else new
    if not methods or set(methods) - set(new):
        raise BenchError(
            f"{module.name} declares {', '.join(new) or 'no policy'}; --methods may name only those"
        )
    base = args.results or Path(f"results/verdict-{module.stem}")
    snapshots = [(r, []) for r in parse_list("--regimes", args.regimes, str)]
    for r, _ in snapshots:
        if r not in REGIMES:
            raise BenchError(f"unknown regime {r!r}; valid: {', '.join(REGIMES)}")
    if args.dataset:
        snapshots.append((PHOTOS, [a for d in args.dataset for a in ("--dataset", str(d))]))
    for name, where in snapshots:
        snapshot, out = ROOT / regime_folder(PUBLISHED, name), base / name
        _snapshot_copy(snapshot, out)
        argv = ["run", *where, "--results", str(out), "--renders", str(args.renders)]
        argv += ["--policy-module", str(module), "--methods", ",".join(methods)]
        argv += snapshot_grid(snapshot, read_runs(snapshot / RUNS))
        argv += ["--workers", str(args.workers)] if args.workers else []
        print("bench " + " ".join(argv))
        sub = build_parser(only="run").parse_args(argv)
        sub.func(sub)
        rows, vocab = read_runs(out / RUNS), read_vocabulary(out)
        frame = headline_frame(rows, vocab, dataset=name == PHOTOS)
        print(f"\n{name}: {out}")
        for method in methods:
            for line in verdict_sentences(category_verdicts(frame, vocab, method)):
                print(f"  {line.replace(', the best at B =', ', at B =')}")  # not a leader
