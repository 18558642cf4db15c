"""`bench run`: the full benchmark (or a grown grid, or a dataset), then its report."""

from __future__ import annotations

import argparse
import dataclasses
from functools import partial
from pathlib import Path

from bench import ROOT, BenchError
from bench.cli.common import (
    LATEST,
    LIST_FORM,
    PUBLISHED,
    QUICK,
    REGIMES,
    add_config_args,
    apply_settings,
    checked_views,
    field_docs,
    parse_list,
    published_snapshots,
    regime_arg,
    regime_folder,
    renders_arg,
    results_arg,
    settings_arg,
    settings_help,
)
from bench.console import log
from bench.render.config import QUICK_RENDER, VARIANTS, RenderConfig

HELP = "run the full benchmark: every scene, seed, method and budget; tables and figures"
DESCRIPTION = (
    "Run every (scene, seed, method, budget) of the grid: render (cached), candidates and "
    "signals (cached), selection, COLMAP matching and verification, then each task (tri: "
    "triangulation with the known poses; sfm: incremental mapping with unknown poses) under "
    "each track protocol, evaluated against ground truth. Each unit's prediction (its "
    "selections, verified matches and models) is stored in RESULTS/models/ and scored from "
    "there. Rows go to RESULTS/runs.csv as they finish; an interrupted run resumes where it "
    "stopped, a grown grid runs only its new rows, and rows whose scoring alone changed are "
    "scored again from the stored predictions (--reevaluate: all of them). The sfm task's "
    "selections see the images and the intrinsics only (the geometry their signals need is "
    "estimated from the images); the tri task's see the rig's poses. Then table1.csv, "
    "table1_twoview.csv, table2.csv, paired.csv, paired_sfm.csv, table_scenes.csv, "
    "frontend_cost.csv, verdicts.csv, table_cost.csv, figure_cost.png, figure2.png, "
    "figure3.png/.pdf, figure_budget.png (with several budgets), the results page "
    "README.md, config.json, vocabulary.json and manifest.json (rows a run replaces go to "
    "runs.stale.csv, never deleted); with --pools also table_pools.csv (each pool's peer "
    "and best selections against colmap-b); with --dataset also transfer.csv, "
    "transfer_ranks.csv and figure_transfer.png (the datasets' ranking against the rendered "
    "one, --rendered) and, with several datasets, table1-<dataset>.csv."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The grid's lists (`_grid_arguments`), the settings (`_settings_arguments`), what
    the grid runs on (`_input_arguments`, `_dataset_arguments`) and where
    (`_folder_arguments`)."""
    _grid_arguments(parser)
    _settings_arguments(parser)
    _input_arguments(parser)
    _dataset_arguments(parser)
    _folder_arguments(parser)


def _list_arg(parser, name: str, default: str | None, metavar: str, what: str) -> None:
    parser.add_argument(
        f"--{name}",
        default=default,
        metavar=metavar,
        help=f"{what}; {LIST_FORM}" + (f" (default: {default})" if default is not None else ""),
    )


def _grid_arguments(parser: argparse.ArgumentParser) -> None:
    """The grid's dimensions: scenes, methods, pools, budgets, tasks, protocols, seeds."""
    from bench.harness.grid import default_methods
    from bench.scenes.spec import scene_names
    from bench.unit.tasks import TASK_RUNNERS
    from bench.vocabulary import FRONTIER_BUDGETS, FRONTIER_PEERS, PROTOCOLS, WHOLE_POOL_BUDGET

    list_arg = partial(_list_arg, parser)
    list_arg("scenes", None, "S1,S2", f"scene types (default: {','.join(scene_names())})")
    list_arg(
        "methods",
        ",".join(default_methods()),
        "M1,M2",
        "methods: the selection policies, the oracle and the stock-COLMAP peers (the "
        "`method` column of runs.csv); with the sfm task on rendered scenes, stock COLMAP with all its features "
        "(colmap) is added if missing: the sfm means leave out the (scene, seed) cells it "
        "does not map",
    )
    list_arg(
        "pools",
        None,
        "P1,P2",
        "the candidate pools the methods run on, each a detector with the matcher its "
        "selections are matched with: sift, aliked, disk, xfeat (their standard matchers: "
        "ratio test, LightGlue, LightGlue, LighterGlue), a learned one with the ratio test as "
        "aliked+ratio, or a --pool-module's; on a pool other than the run's own (--detector) "
        "a method's rows are named <method>:<pool>, and each pool's own top-B peer "
        "(aliked-b, ...) runs too; default: the --detector's pool alone",
    )
    list_arg(
        "budget",
        None,
        "B1,B2",
        "features per view (default: 128,256,512, or 256 with --quick; 256 is the headline); "
        f"a whole-pool method's budget is {WHOLE_POOL_BUDGET}",
    )
    list_arg(
        "frontier",
        None,
        "B1,B2",
        f"budgets at which the category peers {' and '.join(FRONTIER_PEERS)} alone run "
        "besides --budget, so that figure_cost.png draws their frontiers from 128 to 2048 "
        f"(default: {','.join(map(str, FRONTIER_BUDGETS))} on a regime's default budgets; "
        "none with --budget, --quick or --dataset; 'none' runs none)",
    )
    tasks = "; ".join(f"{n} ({r.spec.doc})" for n, r in TASK_RUNNERS.items())
    list_arg(
        "tasks",
        ",".join(n for n, r in TASK_RUNNERS.items() if r.default),
        "T1,T2",
        f"tasks: {tasks}. The nbv task runs alone (--tasks nbv), on each scene's 21-view path "
        "(the nbv.* settings), with the view choosers: its cost (about 2.3 h cold for the "
        "sparse regime's scenes and seeds on two cores, docs/protocol.md) is beyond the "
        "default grid's hour, so it is off by default; --quick --tasks nbv is its smoke run",
    )
    list_arg(
        "protocols",
        ",".join(PROTOCOLS),
        "P1,P2",
        "track protocols, applied to the tri and sfm tasks' triangulation (pairs has none): "
        "multiview (tracks of 3+ views, the headline) and twoview (two-view tracks kept; its "
        "own table)",
    )
    list_arg(
        "seeds",
        None,
        "N1,N2",
        "scene seeds, e.g. 0,1,2 or 0-9 (default: the regime's, 0-4 or 0,1; 0 with --quick)",
    )


def _settings_arguments(parser: argparse.ArgumentParser) -> None:
    """The adaptive policy's weights and every other setting (`--set`)."""
    from bench.frontend.policies import PolicyConfig, Weights, own_fields
    from bench.unit.config import RunConfig
    from bench.vocabulary import SETTINGS

    _list_arg(
        parser,
        "weights",
        ",".join(str(w) for w in dataclasses.astuple(Weights())),
        "W1,...,W5",
        field_docs(PolicyConfig)["weights"].rstrip("."),
    )
    settings_arg(
        parser,
        "any setting of the run, applied after the options above and recorded in "
        "config.json (repeatable; e.g. --set backend.ratio=0.7, --set policy.tiles=8,6, "
        "--set signals.depth_prior=none); settings: "
        + ", ".join(settings_help(RunConfig))
        + "; each method's own (decide its rows alone): "
        + ", ".join(f"{m}.{k}" for m, cls in SETTINGS.items() for k in own_fields(cls)),
    )


def _input_arguments(parser: argparse.ArgumentParser) -> None:
    """What the grid runs on: the smoke preset, the regime, outside policies and pools,
    the detector, the render settings."""
    from bench.frontend.pools import POOLS

    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: tiny renders, one seed, budget 256 (the nbv task: 5 candidates)",
    )
    regime_arg(
        parser,
        "sets the default --views, --seeds (0 with --quick) and --results "
        f"(./{LATEST} or ./{regime_folder(LATEST, 'dense')}; --quick: ./{QUICK} or "
        f"./{regime_folder(QUICK, 'dense')})",
    )
    parser.add_argument(
        "--policy-module",
        action="append",
        default=[],
        metavar="FILE",
        help="a Python file whose @policy functions are registered (repeatable); see "
        "examples/my_policy.py and 'Writing a policy' below",
    )
    parser.add_argument(
        "--pool-module",
        action="append",
        default=[],
        dest="policy_module",
        metavar="FILE",
        help="a Python file that registers a candidate pool of your own detector with "
        "bench.frontend.pools.register_pool (repeatable); name it in --pools or --detector; "
        "see docs/extending.md",
    )
    parser.epilog = policy_guide()
    parser.add_argument(
        "--detector",
        default="sift",
        metavar="POOL",
        help=f"the run's own candidate pool: {', '.join(POOLS)} or a --pool-module's "
        "(default: %(default)s)",
    )
    add_config_args(parser, RenderConfig, quick=QUICK_RENDER, choices={"variant": VARIANTS})


def _dataset_arguments(parser: argparse.ArgumentParser) -> None:
    """A dataset instead of the rendered scenes: its folder, its bags, the rendered
    folders its ranking is compared with."""
    parser.add_argument(
        "--dataset",
        type=Path,
        action="append",
        default=None,
        metavar="DIR",
        help="benchmark on a dataset in the COLMAP layout instead of the rendered scenes "
        "(repeatable; DIR may also be a folder of datasets): DIR/images/, the ground-truth "
        "poses in DIR/sparse/0/ or DIR/sparse/ (text or binary model), optionally "
        "DIR/ground_truth/points.ply (point accuracy) and per-image "
        "DIR/ground_truth/<image>.npz (tracks, completeness, oracle); each dataset is one "
        "scene named by its folder; results default to ./results/dataset-<name>, or "
        "./results/datasets for several",
    )
    parser.add_argument(
        "--bag-size",
        type=int,
        default=None,
        metavar="N",
        help="with --dataset: score random co-visible bags of N images of each dataset, as "
        "the Image Matching Challenge does (default 6, the sparse regime's rig; 14 matches "
        "the dense regime; 0: the whole dataset as one bag); a dataset of at most N images is "
        "one bag; each bag is a seed of its own rows, its images in the `bag` column",
    )
    parser.add_argument(
        "--bags",
        type=int,
        default=None,
        metavar="K",
        help="with --dataset: the bags per dataset (default 10: two halves of 5 for the "
        "split-half reliability, docs/protocol.md)",
    )
    parser.add_argument(
        "--rendered",
        type=Path,
        action="append",
        default=None,
        metavar="DIR",
        help="with --dataset: a rendered results folder whose ranking transfer.csv compares "
        "with the datasets' (repeatable; default: the package's snapshot of each regime, "
        f"{ROOT / PUBLISHED} and {ROOT / regime_folder(PUBLISHED, 'dense')}); each dataset's "
        "`matched` rows are those of the regime nearest its view count",
    )


def _folder_arguments(parser: argparse.ArgumentParser) -> None:
    """Where the run reads and writes, where it runs, and what it does with what the
    results folder holds."""
    results_arg(
        parser,
        None,
        f"results folder (default: the regime's, ./{LATEST}, or ./{QUICK} with --quick; runs never write "
        f"the published snapshot ./{PUBLISHED}, see `bench publish`)",
    )
    renders_arg(parser)
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help="Dask workers of a local cluster, one single-threaded process each (default: the "
        "machine's cores); 1 runs everything in this process, with no cluster",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="submit the units to an existing Dask cluster (e.g. tcp://host:8786) instead; "
        "its workers must see the same renders/ and results folder",
    )
    parser.add_argument(
        "--reevaluate",
        action="store_true",
        help="score every row of the grid again from its stored prediction (selections, "
        "verified matches, models) without selecting, matching or mapping again; a unit "
        "without a current prediction is computed",
    )
    parser.add_argument(
        "--set-aside-damaged",
        action="store_true",
        help="move damaged rows of RESULTS/runs.csv to runs.damaged.csv and compute them again "
        "(without it, a damaged runs.csv is refused)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace results of another configuration in RESULTS",
    )


def policy_guide() -> str:
    """`bench run --help`'s section for policy authors, from the docstrings of the types a
    policy receives."""
    from bench.frontend.features import Candidates
    from bench.frontend.policies import PolicyInput
    from bench.frontend.signals import Signals

    def fields(cls) -> str:
        return "; ".join(f"{k}: {v.rstrip('.')}" for k, v in field_docs(cls).items()) + "."

    return (
        "Writing a policy (--policy-module FILE): decorate `def name(inp, budget, rng, cfg)` "
        "with @bench.frontend.policies.policy('name'); it returns one array of min(budget, N) "
        "distinct integer indices into inp.candidates (not None, not a tuple); rng is a seeded "
        "numpy Generator, cfg the PolicyConfig. A policy that raises or breaks this contract "
        "fails its rows (file:line in runs.csv's failure) and the grid goes on; it may not "
        "read ground truth (bench.frontend.plugins). inp (PolicyInput): "
        f"{fields(PolicyInput)} inp.candidates (Candidates, N keypoints): {fields(Candidates)} "
        f"inp.signals (Signals, each (N,) float64 in [0, 1]): {fields(Signals)}"
    )


def weights_arg(text: str):
    """`--weights wt,wr,wq,wp,wa`: a vector, in the order of `Weights`' fields."""
    from bench.frontend.policies import Weights

    values = parse_list("--weights", text, float, "0.28,0.27,0.22,0.19,0.20", unique=False)
    names = [f.name for f in dataclasses.fields(Weights)]
    if len(values) != len(names):
        raise BenchError(f"weights must be five numbers (t, r, q, p, a), got {list(values)}")
    return Weights(**dict(zip(names, values)))


def run_config(args: argparse.Namespace):
    """The run's settings: the --quick preset, then the options, then each --set."""
    from bench.frontend import plugins
    from bench.frontend.features import DetectorConfig
    from bench.frontend.policies import PolicyConfig
    from bench.unit.config import QUICK_NBV, RunConfig

    render = QUICK_RENDER if args.quick else RenderConfig()
    if args.regime and args.views is None and not args.dataset:
        render = dataclasses.replace(render, views=REGIMES[args.regime][0])
    overrides = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(RenderConfig)
        if getattr(args, f.name) is not None
    }
    render = checked_views(dataclasses.replace(render, **overrides))
    if args.dataset:  # a dataset's images are what they are: nothing renders
        given = [f"--{k.replace('_', '-')}" for k in overrides] + ["--scenes"] * (
            args.scenes is not None
        )
        if given:
            log(f"{', '.join(given)} ignored with --dataset: its images are not rendered")
        render = None
    for m in args.policy_module:
        if Path(m).is_dir():
            raise BenchError(f"--policy-module {m} is a directory; give the module's .py file")
    modules = tuple(str(Path(m).resolve()) for m in args.policy_module)
    plugins.load(modules)  # their policies' own settings may be --set
    run = RunConfig(
        render=render,
        detector=DetectorConfig(detector=args.detector),
        policy=PolicyConfig(weights=weights_arg(args.weights), modules=modules),
    )
    if args.quick:
        run = dataclasses.replace(run, nbv=QUICK_NBV)
    return apply_settings(run, args.settings)


def datasets_arg(paths: list[Path]) -> tuple[Path, ...]:
    """The `--dataset` folders, checked: each a dataset (`images/` and a COLMAP model), or
    a folder whose sub-folders are datasets."""
    from bench.frontend.views import Source

    out = []
    for path in map(Path, paths):
        if not path.exists():
            raise BenchError(f"{path} does not exist")
        if Source.kind(path) == "render":
            raise BenchError(
                f"{path} is a render entry; --dataset takes DIR with images/ and sparse/"
            )
        if not (path / "images").is_dir() and path.is_dir():
            inner = sorted(p for p in path.iterdir() if (p / "images").is_dir())
            for p in inner:
                Source.of(p)
                out.append(p.resolve())
            if inner:
                continue
        Source.of(path)  # a clear error if it is not a dataset
        out.append(path.resolve())
    repeated = sorted({p.name for p in out if out.count(p) > 1})
    if repeated:
        log(
            f"--dataset repeats {', '.join(repeated)}; each runs once (a repeat is not a replicate)"
        )
    return tuple(dict.fromkeys(out))


def rendered_arg(paths: list[Path]) -> list[Path]:
    """The `--rendered` folders, checked before any work: each a results folder of `bench
    run` (its `runs.csv`)."""
    from bench.results import RUNS

    for path in paths:
        if not (Path(path) / RUNS).is_file():
            raise BenchError(
                f"--rendered {path}: no {RUNS} there; give a rendered results folder of `bench run`"
            )
    return list(paths)


def transfer_methods(cfg) -> None:
    """Say before any work when a dataset run's methods, as placed on its pools, are too
    few for a tau."""
    from bench.report.transfer import MIN_METHODS, NEEDS
    from bench.vocabulary import METHODS

    if not all(m in METHODS for m in cfg.methods):
        return  # a name not declared yet: the grid's check says so, in one line
    ranked = [m for m in cfg.placed[0] if not METHODS[m].whole_pool]
    if len(ranked) < MIN_METHODS:
        log(
            f"transfer.csv will hold no tau: --methods gives {len(ranked)} budgeted method(s) "
            f"({', '.join(ranked) or 'none'}); {NEEDS}"
        )


def has_pixel_truth(dataset: Path) -> bool:
    """Whether a dataset has per-pixel ground truth (which the oracle needs)."""
    from bench.evaluation import layers
    from bench.frontend.views import Source

    names = [n for n, _ in Source.of(dataset).cameras()]
    ok = layers.has_pixel_truth(dataset, names)
    if not ok:
        log(f"{dataset} has no per-pixel ground truth: the oracle is left out")
    return ok


def bags_arg(args: argparse.Namespace, datasets: bool, tasks: tuple[str, ...]) -> tuple[int, int]:
    """(`--bag-size`, `--bags`), checked; their defaults with a dataset (one bag of the
    whole dataset where the size is 0, and with a task that reads a path of its own: the
    next-views task chooses among every view of the set)."""
    from bench.unit.bags import DEFAULT_COUNT, DEFAULT_SIZE
    from bench.unit.tasks import TASK_RUNNERS

    given = [n for n, v in (("--bag-size", args.bag_size), ("--bags", args.bags)) if v is not None]
    if given and not datasets:
        log(f"{' and '.join(given)} ignored without --dataset: rendered scenes have their rigs")
    pathed = [t for t in tasks if t in TASK_RUNNERS and TASK_RUNNERS[t].rig is not None]
    if pathed and datasets:
        if given:
            log(f"{' and '.join(given)} ignored with --tasks {pathed[0]}: it reads the whole set")
        return 0, 1
    size = DEFAULT_SIZE if args.bag_size is None else args.bag_size
    count = DEFAULT_COUNT if args.bags is None else args.bags
    if count < 1:
        raise BenchError(f"--bags must be at least 1, got {count}")
    return size, (1 if size == 0 else count)


def grid_of(args: argparse.Namespace):
    """The grid, results folder and options `bench run` would run with `args`:
    (`BenchConfig`, the results folder, `RunOptions`, the rendered folders a dataset run
    is compared with), nothing computed."""
    from bench.harness.execute import Cluster, default_workers
    from bench.harness.grid import BenchConfig, RunOptions, with_reference
    from bench.scenes.spec import scene_names
    from bench.vocabulary import FRONTIER_BUDGETS, GROUND_TRUTH, HEADLINE, METHODS

    if args.scheduler is not None and args.workers is not None:
        raise BenchError("--workers does not apply with --scheduler: the cluster has its workers")
    run_cfg = run_config(args)
    methods = parse_list("--methods", args.methods, str, "texture,adaptive")
    datasets = datasets_arg(args.dataset) if args.dataset else ()
    tasks = parse_list("--tasks", args.tasks, str, HEADLINE[0])
    if args.rendered is not None and not datasets:
        log("--rendered is ignored without --dataset: it is what datasets are compared with")
    rendered = rendered_arg(args.rendered) if args.rendered and datasets else None
    regime = args.regime or "sparse"
    if args.regime and datasets:
        log("--regime is ignored with --dataset: a dataset's views are what they are")
    bag_size, bag_count = bags_arg(args, bool(datasets), tasks)
    if datasets:
        if args.seeds is not None:
            log("--seeds is ignored with --dataset: a dataset's seeds are its bags (--bags)")
        scenes, seeds = tuple(d.name for d in datasets), tuple(range(bag_count))
        truth = all([has_pixel_truth(d) for d in datasets])  # what the oracle selects by
        kinds = {p: METHODS[p].kind for p in methods if p in METHODS}
        methods = tuple(p for p in methods if truth or kinds.get(p) != GROUND_TRUTH)
    else:
        seeds = parse_list(
            "--seeds",
            args.seeds if args.seeds is not None else ("0" if args.quick else REGIMES[regime][1]),
            int,
            "0,1,2 or 100-119",
        )
        scenes = args.scenes if args.scenes is not None else ",".join(scene_names())
        scenes = parse_list("--scenes", scenes, str, "table,facade")
        methods = with_reference(methods, tasks)
    budget = args.budget if args.budget is not None else ("256" if args.quick else "128,256,512")
    default_frontier = args.quick or datasets or args.budget is not None
    frontier = args.frontier or (
        "none" if default_frontier else ",".join(map(str, FRONTIER_BUDGETS))
    )
    cfg = BenchConfig(
        scenes=scenes,
        seeds=seeds,
        methods=methods,
        budgets=parse_list("--budget", budget, int, "128,256,512"),
        tasks=tasks,
        protocols=parse_list("--protocols", args.protocols, str, "multiview,twoview"),
        run=run_cfg,
        datasets=tuple(map(str, datasets)),
        bag_size=bag_size,
        frontier=() if frontier == "none" else parse_list("--frontier", frontier, int, "1024,2048"),
        pools=parse_list("--pools", args.pools, str, "sift,aliked") if args.pools else (),
    )
    if datasets:
        transfer_methods(cfg)
    results = args.results or (
        LATEST.with_name(f"dataset-{datasets[0].name}" if len(datasets) == 1 else "datasets")
        if datasets
        else regime_folder(QUICK if args.quick else LATEST, regime)
    )
    if args.workers is not None and args.workers < 1:
        raise BenchError(f"--workers must be at least 1, got {args.workers}")
    options = RunOptions(
        overwrite=args.overwrite,
        set_aside=args.set_aside_damaged,
        reevaluate=args.reevaluate,
        cluster=Cluster(args.workers or default_workers(), args.scheduler),
    )
    return cfg, results, options, rendered


def run(args: argparse.Namespace) -> None:
    from bench.binding import read_vocabulary
    from bench.failures import errors
    from bench.harness.grid import in_grid, run_benchmark
    from bench.report.page import brief_table1
    from bench.report.write import write_report
    from bench.results import PAGE, Workspace

    cfg, results, options, rendered = grid_of(args)
    written = []  # the Table 1 the report drew, to print
    report = partial(write_report, rendered=rendered or published_snapshots())
    run_report = lambda *a: written.append(report(*a))  # noqa: E731
    df = run_benchmark(cfg, Workspace(results, args.renders), options, report=run_report)
    if written and written[0] is not None:
        protocol = "multiview" if "multiview" in cfg.protocols else cfg.protocols[0]
        print(
            f"Table 1 ({protocol} protocol; {', '.join(cfg.tasks)}; {results / PAGE} has the rest):"
        )
        print(brief_table1(written[0], read_vocabulary(results)))
    failed = errors(in_grid(cfg, df))
    if failed:  # after every other row and the tables are written
        raise BenchError(f"{failed}; every other row and the tables are written")
