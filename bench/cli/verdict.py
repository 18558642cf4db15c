"""`bench verdict MODULE`: a policy module's rows computed beside the published snapshots,
read in place, and its verdict against the stock-COLMAP peer of its category."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path

from bench import ROOT, BenchError
from bench.cli.common import (
    PHOTOS,
    POOLS_RUN,
    PUBLISHED,
    REGIMES,
    parse_list,
    regime_folder,
    renders_arg,
    snapshot_grid,
)

HELP = "your policy module's verdict against the published snapshots (its rows alone computed)"
DESCRIPTION = (
    "Compute only the rows of MODULE's policies (every method it declares, or --methods) "
    "into --results/<snapshot>/, at each published snapshot's grid budgets (never the cost "
    "frontier's), tasks and cells, under its settings, from the reference renders (--regimes; "
    "with --dataset the photo sets' bags too); then print, for each snapshot, a header naming "
    "it (version, commit, reference renders), and for each method, budget and headline "
    "metric its verdict against the stock-COLMAP peer of its category (`image`: colmap-b; "
    "`views`: colmap-tracks-b), paired over the snapshot's cells with a 95 % interval, or "
    "the line that says why there is none. The snapshots are read where they are and never "
    "changed. Pairing needs the same protocol (settings, libraries, the fields that decide a "
    "row) and the same pixels; where the code differs from a snapshot's, the modules are "
    "named and one cell of its peers is computed again, as `bench reproduce` does, and "
    "compared before the verdict. A second call resumes; editing the module recomputes its "
    "rows alone. A pool module (one that registers a candidate pool: docs/extending.md) is "
    "judged against the cross-pool snapshot (results/published-pools) alone: its pool's own "
    "top-B (`<pool>-b`, or `response:<pool>` on a pool matched by the ratio test) and the "
    "snapshot's selections that run on any pool (or --methods of them), each on its pool "
    "with its matcher. Exit 1 when no verdict at all could be made."
)
REPRODUCED = ("facade", 0, 256)
"""The cell of a rendered snapshot's peers computed again where the code differs (scene,
seed, budget; where the snapshot lacks one, its first scene or seed, its middle budget)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "module", type=Path, metavar="MODULE", help="a policy module or a pool module (.py)"
    )
    parser.add_argument(
        "--methods",
        default=None,
        help="its methods to run (default: all; a pool module: the snapshot's selections)",
    )
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


def _checked(args: argparse.Namespace) -> tuple[Path, list[tuple[str, list[str]]]]:
    """The module and the snapshots to judge against (name, `--dataset` options), every
    input checked before any work."""
    from bench.cli.run import datasets_arg

    module = args.module.resolve()
    if not module.is_file():
        raise BenchError(f"{args.module} is not a file (a policy module, .py)")
    try:
        module.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise BenchError(f"{args.module} is not UTF-8 text (byte {e.start}): not a module") from e
    if args.workers is not None and args.workers < 1:
        raise BenchError(f"--workers must be at least 1, got {args.workers}")
    snapshots = []
    for r in parse_list("--regimes", args.regimes, str):
        if r not in REGIMES:
            raise BenchError(f"unknown regime {r!r}; valid: {', '.join(REGIMES)}")
        snapshots.append((r, []))
    if args.dataset:
        datasets_arg(args.dataset)
        snapshots.append((PHOTOS, [a for d in args.dataset for a in ("--dataset", str(d))]))
    return module, snapshots


def run(args: argparse.Namespace) -> None:
    from bench.frontend import plugins
    from bench.frontend.pools import ORIGIN as POOL_ORIGIN
    from bench.harness.origin import read_origin
    from bench.unit import declared  # noqa: F401 (every method of the package, first)

    module, snapshots = _checked(args)
    plugins.load((str(module),))  # the package's methods imported first: not the module's
    pools = sorted(p for p, origin in POOL_ORIGIN.items() if Path(origin) == module)
    if pools:  # a pool module: the cross-pool snapshot alone
        snapshots = [(POOLS_RUN, [])]
    folders = {name: ROOT / regime_folder(PUBLISHED, name) for name, _ in snapshots}
    origins = {name: read_origin(folder) for name, folder in folders.items()}
    if pools:
        methods = _on_pools(args, pools, folders[POOLS_RUN])
    else:
        new = sorted(m for m, origin in plugins.ORIGIN.items() if Path(origin) == module)
        methods = parse_list("--methods", args.methods, str) if args.methods else new
        if not methods or set(methods) - set(new):
            raise BenchError(
                f"{module.name} declares {', '.join(new) or 'no policy'}; --methods may name "
                "only those"
            )
    base = args.results or Path(f"results/verdict-{module.stem}")
    judged = 0
    for name, where in snapshots:
        snapshot = Snapshot(name, folders[name], origins[name], where)
        judged += _judge(args, module, methods, snapshot, base)
    if not judged:
        raise SystemExit(1)


def _on_pools(args, pools: list[str], snapshot: Path) -> list[str]:
    """A pool module's methods (`DESCRIPTION`), declared on each of its pools."""
    from bench.frontend.pools import POOLS, PoolSpec
    from bench.results import RUNS
    from bench.runs import read_runs
    from bench.unit.pooled import POOLED_KINDS, SEPARATOR, declare_pooled, pool_peer
    from bench.vocabulary import METHODS

    names = {m.partition(SEPARATOR)[0] for m in set(read_runs(snapshot / RUNS)["method"])}
    free = sorted(m for m in names if METHODS[m].kind in POOLED_KINDS and not METHODS[m].pool)
    chosen = parse_list("--methods", args.methods, str) if args.methods else free
    if not chosen or set(chosen) - set(free):
        raise BenchError(
            f"{snapshot} runs {', '.join(free) or 'no selection'} on every pool; --methods "
            "may name only those"
        )
    out = []
    for pool in pools:
        spec = PoolSpec(pool, POOLS[pool].matcher)
        out.append(pool_peer(pool) or declare_pooled("response", spec))
        out += [declare_pooled(m, spec) for m in chosen]
    return out


@dataclass(frozen=True)
class Snapshot:
    """A published snapshot judged against: its name, folder, origin and the `bench run`
    options that name its photo sets (none for a rendered one)."""

    name: str
    folder: Path
    origin: dict
    where: list[str]


def _judge(args, module: Path, methods: list[str], snap: Snapshot, base: Path) -> int:
    """Compute the module's rows beside one snapshot and print their verdicts; how many."""
    from bench.binding import read_settings
    from bench.harness.grid import run_benchmark
    from bench.harness.origin import changed_modules, header, protocol_changes
    from bench.results import RUNS, Workspace
    from bench.runs import read_runs

    name, snapshot, origin = snap.name, snap.folder, snap.origin
    print(f"\n{name}: judged against {snapshot}: {header(origin)}")
    published = read_runs(snapshot / RUNS)
    budgets = grid_budgets(published)
    argv = _module_argv(args, module, methods, snap, published, budgets, base / name)
    cfg, options, out = _module_grid(argv, module, snapshot, methods)
    peers = _peer_pairs(published, cfg.tasks)
    refused = protocol_changes(origin, cfg.run, peers)
    for line in refused.values():
        print(f"  not paired: {line}")
    changed = changed_modules(origin)
    if changed:
        print(
            f"  the code differs from the snapshot's in {len(changed)} module(s): {', '.join(changed)}"
        )
        if read_settings(snapshot)["render"] is not None:
            again = base / f"reproduce-{name}"
            paired = [p for p in peers if p not in refused]  # none it cannot compute here
            _reproduce_peers(args, snapshot, published, paired, budgets, again)
        else:
            print("  (its peers are not computed again on photographs: `bench reproduce` a regime)")
    else:
        print("  the code is the snapshot's (every module's hash the same)")
    run_benchmark(cfg, Workspace(out, args.renders), options)
    return _print_verdicts(published, out, methods, budgets, refused, name == PHOTOS)


def grid_budgets(rows) -> list[int]:
    """The budgets of a snapshot's grid: those its policies ran at (the cost frontier's,
    where the frontier peers alone ran, are not)."""
    from bench.vocabulary import FRONTIER_PEERS

    policies = rows[~rows["method"].isin(FRONTIER_PEERS) & (rows["budget"] > 0)]
    return sorted(int(b) for b in set(policies["budget"]))


def _peer_pairs(published, tasks) -> list[tuple[str, str]]:
    """The (method, task) of the snapshot's rows a verdict reads: the category peers' and
    stock COLMAP's (the sfm means' exclusion rule)."""
    from bench.vocabulary import CATEGORY_PEERS, REFERENCE_PEER

    peers = published[published["method"].isin((*CATEGORY_PEERS, REFERENCE_PEER))]
    return sorted({(m, t) for m, t in zip(peers["method"], peers["task"]) if t in tasks})


def _module_argv(args, module, methods, snap: Snapshot, published, budgets, out) -> list[str]:
    """`bench run`'s options for the module's rows beside a snapshot: its cells, tasks and
    protocols at its grid budgets, the module's methods alone."""
    argv = ["run", *snap.where, "--results", str(out), "--renders", str(args.renders)]
    argv += ["--policy-module", str(module), "--methods", ",".join(methods), "--frontier", "none"]
    argv += snapshot_grid(snap.folder, published)
    argv[argv.index("--budget") + 1] = ",".join(map(str, budgets))
    if snap.name == POOLS_RUN:  # the module's pools, with their matchers, alone
        if "--pools" in argv:
            del argv[argv.index("--pools") : argv.index("--pools") + 2]
        from bench.frontend.pools import PoolSpec
        from bench.vocabulary import METHODS

        specs = {str(PoolSpec(METHODS[m].pool, METHODS[m].matcher)): 0 for m in methods}
        argv += ["--pools", ",".join(specs)]
    return argv + (["--workers", str(args.workers)] if args.workers else [])


def _module_grid(argv: list[str], module: Path, snapshot: Path, methods: list[str]):
    """The grid of `argv` under the snapshot's own settings (`config.json`), the module's
    methods alone: (`BenchConfig`, `RunOptions`, the results folder)."""
    from bench.binding import read_settings
    from bench.cli import build_parser
    from bench.cli.common import settings_config
    from bench.cli.run import grid_of

    print("  bench " + " ".join(argv))
    cfg, results, options, _ = grid_of(build_parser(only="run").parse_args(argv))
    own = settings_config(read_settings(snapshot))
    run = dataclasses.replace(own, policy=dataclasses.replace(own.policy, modules=(str(module),)))
    return dataclasses.replace(cfg, methods=tuple(methods), run=run), options, results


def _reproduce_peers(args, snapshot, published, peers, budgets, out) -> None:
    """One cell of the snapshot's peers computed again and compared (`bench reproduce`)."""
    from bench.cli.reproduce import reproduce_slice

    scenes, seeds = sorted(set(published["scene"])), sorted(set(published["seed"]))
    scene, seed, budget = REPRODUCED
    scene = scene if scene in scenes else scenes[0]
    seed = seed if seed in seeds else seeds[0]
    budget = budget if budget in budgets else budgets[len(budgets) // 2]
    cell = (published["scene"] == scene) & (published["seed"] == seed)
    cell &= published["budget"].isin((budget, 0)) & published["method"].isin({m for m, _ in peers})
    print(f"  its peers' cell {scene} seed {seed} at {budget} computed again:")
    result = reproduce_slice(snapshot, published[cell], out, args.renders, args.workers)
    print("\n".join(f"  {line}" for line in result.lines()))


def _print_verdicts(published, out, methods, budgets, refused, dataset) -> int:
    """Each method's verdict at each budget and ranking metric, or why there is none."""
    import pandas as pd

    from bench.report.categories import category_verdicts, peer_metrics, unjudged, verdict_sentence
    from bench.report.tables import headline_frame
    from bench.results import RUNS
    from bench.runs import check_pixels, mark_reference, read_runs
    from bench.vocabulary import Vocabulary

    vocab = Vocabulary.current()
    pairs = pd.Series(list(zip(published["method"], published["task"])), index=published.index)
    theirs = published[~published["method"].isin(methods) & ~pairs.isin(list(refused))]
    theirs = theirs[theirs["budget"].isin((0, *budgets))]  # never the frontier's rows
    mine = read_runs(out / RUNS, vocab)
    mine = mine[mine["method"].isin(methods) & mine["budget"].isin(budgets)]
    rows = pd.concat([theirs, mine], ignore_index=True)
    check_pixels(rows, f"{out} beside the snapshot")
    frame = headline_frame(mark_reference(rows, vocab), vocab, dataset=dataset)
    present = list(pd.unique(rows["method"]))
    missing = unjudged(vocab, present)
    judged = 0
    for method in methods:
        verdicts = category_verdicts(frame, vocab, method)
        for metric in peer_metrics(vocab):
            for budget in budgets:
                at = verdicts
                if len(at):
                    at = at[(at["budget"] == budget) & (at["metric"] == metric)]
                if len(at):
                    line = verdict_sentence(at.iloc[0]).replace(", the best at B =", ", at B =")
                    judged += 1
                else:
                    why = _why_not(frame, method, metric, budget, missing, vocab)
                    line = f"`{method}` at B = {budget} in `{metric}`: no verdict: {why}"
                print(f"  {line}")
    return judged


def _why_not(frame, method, metric, budget, missing, vocab) -> str:
    """Why a method has no verdict at a budget in a metric."""
    from bench.report.tables import errored

    if method in errored(frame, vocab):
        return "its policy raised or broke its contract (its rows are failures)"
    if metric not in frame:
        return "the snapshot has no rows of that task"
    mine = frame[(frame["method"] == method) & (frame["budget"] == budget)]
    if mine.empty or mine[metric].isna().all():
        return "it has no rows of that task here (its kind does not run it)"
    for line in missing:
        if f"`{method}`" in line:
            return line
    return "no cell holds both it and its category's peer"
