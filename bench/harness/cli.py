"""The `bench` command line: scenes, render, run, plot, publish, gallery, train-weights,
select, export."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import signal
import sys
from functools import cache
from pathlib import Path

from bench import DISTRIBUTION, ROOT, BenchError, __version__
from bench.console import log
from bench.frontend.features import DETECTORS, DetectorConfig
from bench.frontend.policies import SHIPPED_WEIGHTS, PolicyConfig, Weights
from bench.render.config import QUICK_RENDER, VARIANTS, RenderConfig


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of a dataclass, keyed by field name."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        body = ast.parse(inspect.cleandoc("\n" + inspect.getsource(klass))).body[0].body
        for node, nxt in zip(body, body[1:]):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant)
            ):
                docs[node.target.id] = " ".join(str(nxt.value.value).split())
    return docs


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of the CLI."""

    def error(self, message: str):
        if message.startswith("unrecognized arguments"):
            message += f" (list options take {LIST_FORM}, e.g. --scenes table,facade)"
        self.exit(2, f"bench: error: {message} (see `{self.prog} --help`)\n")


def add_config_args(parser: argparse.ArgumentParser, cls: type, quick=None) -> None:
    """One `--option` per dataclass field, its docstring as help and its default shown.
    With a `quick` preset the options default to None (the preset or the class default is
    chosen later, by --quick) and the help names both defaults."""
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        kind = {"choices": VARIANTS} if f.name == "variant" else {"type": type(f.default)}
        if quick is None:
            default, shown = f.default, "%(default)s"
        else:
            default, shown = None, f"{f.default}, or {getattr(quick, f.name)} with --quick"
        parser.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            default=default,
            **kind,
            help=f"{docs.get(f.name, '')} (default: {shown})",
        )


def config_from_args(cls: type, args: argparse.Namespace):
    return cls(
        **{f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if hasattr(args, f.name)}
    )


def cmd_scenes(args: argparse.Namespace) -> None:
    from bench.scenes.spec import load_spec, scene_names

    for name in scene_names():
        spec = load_spec(name)
        print(f"{name}: {spec.description}")
        for k, v in spec.params.items():
            print(f"    {k} = {v!r:<10} {spec.docs.get(k, '')}")


def cmd_render(args: argparse.Namespace) -> None:
    from bench.render.entry import render_scene

    cfg = config_from_args(RenderConfig, args).validate()
    entry = render_scene(args.scene, args.seed, cfg, args.renders, force=args.force)
    print(entry)


def cmd_gallery(args: argparse.Namespace) -> None:
    from bench.render.entry import render_scene
    from bench.render.gallery import write_gallery
    from bench.scenes.spec import scene_names

    cfg = config_from_args(RenderConfig, args).validate()
    entries = {name: render_scene(name, args.seed, cfg, args.renders) for name in scene_names()}
    print(write_gallery(entries, args.out))


LIST_FORM = "one comma-separated list without spaces"


def parse_list(
    option: str, text: str, kind: type = str, example: str = "", unique: bool = True
) -> tuple:
    """The items of a list option, which has one syntax: `--option a,b,c`. Integer items of
    `--seeds` may also be inclusive ranges such as 100-119. A repeated item runs once,
    unless the list is a vector (`unique` False)."""
    how = f"{option} takes {LIST_FORM}, e.g. {option} {example}"
    if any(not x.strip() for x in text.split(",")):
        raise BenchError(f"{how}; got {text!r}")
    items = []
    try:
        for x in text.split(","):
            lo, dash, hi = (
                x.partition("-") if option == "--seeds" and x[1:].count("-") else (x, "", "")
            )
            if dash and int(hi) < int(lo):
                raise BenchError(f"{how}; the range {x} is empty (write it low-high)")
            items += list(range(int(lo), int(hi) + 1)) if dash else [kind(x)]
    except ValueError:
        raise BenchError(f"{how}; {text!r} is not a list of {kind.__name__}") from None
    if not unique:
        return tuple(items)
    unique = tuple(dict.fromkeys(items))
    if len(unique) < len(items):
        repeated = sorted({str(x) for x in items if items.count(x) > 1})
        log(f"{option} repeats {', '.join(repeated)}; each runs once (a repeat is not a replicate)")
    return unique


def weights_arg(text: str) -> Weights:
    """`--weights wt,wr,wq,wp,wa`: a vector, in the order of `Weights`' fields."""
    values = parse_list("--weights", text, float, "0.28,0.27,0.22,0.19,0.20", unique=False)
    names = [f.name for f in dataclasses.fields(Weights)]
    if len(values) != len(names):
        raise BenchError(f"weights must be five numbers (t, r, q, p, a), got {list(values)}")
    return Weights(**dict(zip(names, values)))


def cmd_run(args: argparse.Namespace) -> None:
    from bench.harness.execute import default_workers
    from bench.harness.grid import BenchConfig, run_benchmark
    from bench.harness.pipeline import RunConfig
    from bench.harness.tables import headline_frame, table1, with_oracle_share
    from bench.scenes.spec import scene_names

    render = QUICK_RENDER if args.quick else RenderConfig()
    overrides = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(RenderConfig)
        if getattr(args, f.name) is not None
    }
    render = dataclasses.replace(render, **overrides)
    if args.dataset is not None:  # a dataset's images are what they are: nothing renders
        given = [f"--{k.replace('_', '-')}" for k in overrides] + ["--scenes"] * bool(args.scenes)
        if given:
            log(f"{', '.join(given)} ignored with --dataset: its images are not rendered")
        render = None
    if args.scheduler is not None and args.workers is not None:
        raise BenchError("--workers does not apply with --scheduler: the cluster has its workers")
    modules = tuple(str(Path(m).resolve()) for m in args.policy_module)
    run = RunConfig(
        render=render,
        detector=DetectorConfig(detector=args.detector),
        policy=PolicyConfig(
            weights=weights_arg(args.weights),
            modules=modules,
        ),
    )
    policies = parse_list("--policies", args.policies, str, "texture,adaptive")
    if args.dataset is not None:
        dataset = dataset_arg(args.dataset)
        if args.seeds is not None:
            log("--seeds is ignored with --dataset: a dataset is one scene, recorded as seed 0")
        scenes, seeds = (dataset.name,), (0,)
        policies = tuple(p for p in policies if p != "oracle" or has_pixel_truth(dataset))
    else:
        seeds = parse_list(
            "--seeds", args.seeds or ("0" if args.quick else "0,1,2"), int, "0,1,2 or 100-119"
        )
        scenes = parse_list("--scenes", args.scenes or ",".join(scene_names()), str, "table,facade")
    budget = args.budget if args.budget is not None else ("256" if args.quick else "128,256,512")
    cfg = BenchConfig(
        scenes,
        seeds,
        policies,
        parse_list("--budget", budget, int, "128,256,512"),
        parse_list("--tasks", args.tasks, str, "tri"),
        parse_list("--protocols", args.protocols, str, "multiview,twoview"),
        run,
        str(dataset) if args.dataset is not None else None,
    )
    results = args.results or (
        QUICK
        if args.quick
        else LATEST.with_name(f"dataset-{dataset.name}")
        if args.dataset
        else LATEST
    )
    if args.workers is not None and args.workers < 1:
        raise BenchError(f"--workers must be at least 1, got {args.workers}")
    workers = args.workers or default_workers()
    df = run_benchmark(
        cfg,
        results,
        args.renders,
        overwrite=args.overwrite,
        set_aside=args.set_aside_damaged,
        workers=workers,
        scheduler=args.scheduler,
    )
    protocol = "multiview" if "multiview" in cfg.protocols else cfg.protocols[0]
    t = table1(headline_frame(with_oracle_share(df), protocol))
    print(f"Table 1 ({protocol} protocol; {', '.join(cfg.tasks)}):")
    cols = ["strategy", "budget", "runs", "acc_completeness_pct", "completeness_vs_oracle_pct"]
    cols += [
        "accuracy_pct",
        "rmse",
        "median_error",
        "inlier_pct",
        "sfm_maa",
        "sfm_registered_views",
    ]
    print(t[[c for c in cols if c in t]].to_string(index=False, float_format=lambda x: f"{x:.3f}"))


def cmd_plot(args: argparse.Namespace) -> None:
    from bench.harness.report import write_report
    from bench.harness.runs import read_runs

    write_report(read_runs(args.results / "runs.csv"), args.results, args.renders)
    print(f"tables and figures rewritten in {args.results}")


def cmd_publish(args: argparse.Namespace) -> None:
    from bench.harness.report import publish

    print(f"published {publish(args.results, args.to)} files of {args.results} in {args.to}")


def dataset_arg(path: Path) -> Path:
    """A `--dataset` folder, checked: `images/` and a model in `sparse/`."""
    from bench.frontend.views import Source

    Source.of(path)  # a clear error if it is not a dataset
    if (Path(path) / "meta.json").is_file():
        raise BenchError(f"{path} is a render entry; --dataset takes DIR with images/ and sparse/")
    return Path(path).resolve()


def has_pixel_truth(dataset: Path) -> bool:
    """Whether a dataset has per-pixel ground truth (which the oracle needs)."""
    from bench.evaluation import groundtruth
    from bench.frontend.views import read_colmap_model

    names = [n for n, _ in read_colmap_model(dataset / "sparse")]
    ok = groundtruth.has_pixel_truth(dataset, names)
    if not ok:
        log(f"{dataset} has no per-pixel ground truth: the oracle is left out")
    return ok


def cmd_train_weights(args: argparse.Namespace) -> None:
    from bench.harness.pipeline import RunConfig
    from bench.harness.training import train_weights
    from bench.scenes.spec import load_spec

    seeds = parse_list("--seeds", args.seeds, int, "100-119")
    scenes = parse_list("--scenes", args.scenes, str, "table,facade")
    for s in scenes:
        load_spec(s)
    w = train_weights(list(scenes), list(seeds), RunConfig(), args.renders, args.out)
    for k, v in w["weights"].items():
        print(f"{k:<16} learned {v:+.3f}   paper {w['paper_weights'][k]:+.2f}")


def cmd_select(args: argparse.Namespace) -> None:
    from bench.harness.select import select_to_database

    if args.budget <= 0 or args.max_candidates <= 0:
        raise BenchError("--budget and --max-candidates must be positive")
    out = select_to_database(
        args.images,
        args.out,
        args.policy,
        args.budget,
        cameras=args.cameras,
        match=args.match,
        overlays=args.overlays,
        policy_modules=tuple(args.policy_module),
        max_candidates=args.max_candidates,
    )
    print(out)


def cmd_export(args: argparse.Namespace) -> None:
    from bench.harness.export import export_dataset
    from bench.render.entry import render_scene

    entry = render_scene(
        args.scene, args.seed, config_from_args(RenderConfig, args).validate(), args.renders
    )
    print(export_dataset(entry, args.out))


LATEST, QUICK, PUBLISHED = Path("results/latest"), Path("results/quick"), Path("results/published")
"""Default results folders, relative to the current directory. Runs never write to the
published snapshot; only `bench publish` does."""


def _renders_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--renders",
        type=Path,
        default=ROOT / "renders",
        help=f"render cache directory (default: {ROOT / 'renders'})",
    )


def _results_arg(parser: argparse.ArgumentParser, default: Path | None, what: str) -> None:
    parser.add_argument("--results", type=Path, default=default, help=what)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="bench",
        description="Rendered-scene benchmark of keypoint selection policies for 3D reconstruction.",
    )
    p.add_argument("--version", action="version", version=f"bench {__version__} ({DISTRIBUTION})")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser(
        "scenes",
        help="list the scene types and their parameters",
        description="List every scene type (scenes/<name>.toml) with its description and each "
        "parameter's value and meaning.",
    )
    s.set_defaults(func=cmd_scenes)

    r = sub.add_parser(
        "render",
        help="render one scene (six views + ground truth) into the render cache",
        description="Path-trace the six views of SCENE with their ground-truth layers into "
        "renders/<scene>-s<seed>-<key>/. A complete cached entry is reused unless --force.",
    )
    r.add_argument("scene", metavar="SCENE", help="scene type (see `bench scenes`)")
    r.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(r, RenderConfig)
    r.add_argument(
        "--force", action="store_true", help="render again even if a complete entry exists"
    )
    _renders_arg(r)
    r.set_defaults(func=cmd_render)

    from bench.backend.reconstruction import PROTOCOLS
    from bench.harness.grid import DEFAULT_POLICIES
    from bench.harness.pipeline import TASKS
    from bench.scenes.spec import scene_names

    u = sub.add_parser(
        "run",
        help="run the full benchmark: every scene, seed, policy and budget; tables and figures",
        description="Run every (scene, seed, policy, budget) of the grid: render (cached), "
        "candidates and signals (cached), selection, COLMAP matching and verification, then "
        "each task (tri: triangulation with the known poses; sfm: incremental mapping with "
        "unknown poses) under each track protocol, evaluated against ground truth. Rows go to "
        "RESULTS/runs.csv as they finish; an interrupted run resumes where it stopped, and a "
        "grown grid runs only its new rows. The sfm task's selections see the images and the "
        "intrinsics only (the geometry their signals need is estimated from the images); the "
        "tri task's see the rig's poses. Then table1.csv, table1_twoview.csv, table2.csv, "
        "paired.csv, paired_sfm.csv, table_scenes.csv, frontend_cost.csv, figure2.png, "
        "figure3.png/.pdf, figure_budget.png and manifest.json.",
    )

    def list_arg(name: str, default: str | None, metavar: str, what: str) -> None:
        u.add_argument(
            f"--{name}",
            default=default,
            metavar=metavar,
            help=f"{what}; {LIST_FORM}" + (f" (default: {default})" if default is not None else ""),
        )

    list_arg("scenes", None, "S1,S2", f"scene types (default: {','.join(scene_names())})")
    list_arg("policies", ",".join(DEFAULT_POLICIES), "P1,P2", "policies")
    list_arg(
        "budget",
        None,
        "B1,B2",
        "features per view (default: 128,256,512, or 256 with --quick; 256 is the headline; "
        "`all` runs once per scene and seed, as budget 0)",
    )
    list_arg(
        "tasks",
        ",".join(TASKS),
        "T1,T2",
        "reconstruction tasks: tri (known poses, scored against the ground-truth surface) and sfm (unknown poses, scored by pose mAA)",
    )
    list_arg(
        "protocols",
        ",".join(PROTOCOLS),
        "P1,P2",
        "track protocols, applied to both tasks' triangulation: multiview (tracks of 3+ "
        "views, the headline) and twoview (two-view tracks kept; its own table)",
    )
    list_arg(
        "seeds", None, "N1,N2", "scene seeds, e.g. 0,1,2 or 0-9 (default: 0,1,2, or 0 with --quick)"
    )
    list_arg(
        "weights",
        ",".join(str(w) for w in dataclasses.astuple(Weights())),
        "W1,...,W5",
        field_docs(PolicyConfig)["weights"].rstrip("."),
    )
    u.add_argument(
        "--quick", action="store_true", help="smoke run: tiny renders, one seed, budget 256"
    )
    u.add_argument(
        "--dataset",
        type=Path,
        default=None,
        metavar="DIR",
        help="benchmark on a dataset in the COLMAP layout instead of the rendered scenes: "
        "DIR/images/, the ground-truth poses in DIR/sparse/ (cameras.txt, images.txt), "
        "optionally DIR/ground_truth/points.ply (point accuracy) and per-image "
        "DIR/ground_truth/<image>.npz (tracks, completeness, oracle); results default to "
        "./results/dataset-<name>",
    )
    u.add_argument(
        "--policy-module",
        action="append",
        default=[],
        metavar="FILE",
        help="a Python file whose @policy functions are registered (repeatable); see "
        "examples/my_policy.py",
    )
    u.add_argument(
        "--detector",
        default="sift",
        choices=DETECTORS,
        help="candidate detector (default: %(default)s)",
    )
    add_config_args(u, RenderConfig, quick=QUICK_RENDER)
    _results_arg(
        u,
        None,
        f"results folder (default: ./{LATEST}, or ./{QUICK} with --quick; runs never write "
        f"the published snapshot ./{PUBLISHED}, see `bench publish`)",
    )
    _renders_arg(u)
    u.add_argument(
        "--workers",
        type=int,
        default=None,
        help="Dask workers of a local cluster, one single-threaded process each (default: the "
        "machine's cores); 1 runs everything in this process, with no cluster",
    )
    u.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="submit the units to an existing Dask cluster (e.g. tcp://host:8786) instead; "
        "its workers must see the same renders/ and results folder",
    )
    u.add_argument(
        "--set-aside-damaged",
        action="store_true",
        help="move damaged rows of RESULTS/runs.csv to runs.damaged.csv and compute them again "
        "(without it, a damaged runs.csv is refused)",
    )
    u.add_argument(
        "--overwrite",
        action="store_true",
        help="replace results of another configuration in RESULTS",
    )
    u.set_defaults(func=cmd_run)

    pl = sub.add_parser(
        "plot",
        help="rebuild the tables and figures from runs.csv (no rendering, no reconstruction)",
        description="Rewrite table1.csv, table1_twoview.csv, table2.csv, paired.csv, "
        "paired_sfm.csv, table_scenes.csv, frontend_cost.csv, figure3.png/.pdf and "
        "figure_budget.png from RESULTS/runs.csv alone, and figure2.png from it plus the "
        "exported model and the cached render.",
    )
    _results_arg(pl, LATEST, f"results folder (default: ./{LATEST})")
    _renders_arg(pl)
    pl.set_defaults(func=cmd_plot)

    pb = sub.add_parser(
        "publish",
        help="copy a results folder's runs, tables and figures into the published snapshot",
        description="Check RESULTS/runs.csv row by row, then copy it with config.json, "
        "manifest.json, the tables and the figures into TO (the snapshot the repository "
        "tracks), removing report files there that RESULTS does not have.",
    )
    _results_arg(pb, LATEST, f"results folder to publish (default: ./{LATEST})")
    pb.add_argument(
        "--to", type=Path, default=PUBLISHED, help=f"snapshot folder (default: ./{PUBLISHED})"
    )
    pb.set_defaults(func=cmd_publish)

    tw = sub.add_parser(
        "train-weights",
        help="fit the `learned` policy's weights on training seeds",
        description="Render (or reuse) every scene at the training seeds, match and "
        "triangulate each whole candidate pool with the known poses, label every candidate "
        "by whether it observes a point within 0.10 of the ground-truth surface, and fit a "
        "logistic model of that label on the five adaptive signals. Writes the weights with "
        "their provenance (seeds, scenes, code hash, settings). A benchmark whose seeds meet "
        "the training seeds is refused.",
    )
    tw.add_argument("--seeds", default="100-102", help="training seeds (default: %(default)s)")
    tw.add_argument(
        "--scenes", default=",".join(scene_names()), help="scene types (default: %(default)s)"
    )
    tw.add_argument(
        "--out",
        type=Path,
        default=SHIPPED_WEIGHTS,
        help="weights file (default: the one shipped with the package, %(default)s)",
    )
    _renders_arg(tw)
    tw.set_defaults(func=cmd_train_weights)

    se = sub.add_parser(
        "select",
        help="select B keypoints per image of your own photographs into a COLMAP database",
        description="Detect the candidate pool on every JPEG/PNG image in DIR (two or more, "
        "any size), compute the signals, select B per image with POLICY and write "
        "OUT/database.db: cameras, images, the selected keypoints and their SIFT descriptors "
        "in COLMAP's format (COLMAP's matchers and mapper accept it). Calibration from "
        "--cameras (a COLMAP model with poses) or else one camera per image size from the "
        "focal-length prior (EXIF 35 mm equivalent, else 1.2 x max(width, height)); without "
        "poses the parallax, cross-view ambiguity and epipolar signals are off.",
    )
    se.add_argument("--images", type=Path, required=True, metavar="DIR", help="image folder")
    se.add_argument("--policy", default="adaptive", help="selection policy (default: %(default)s)")
    se.add_argument(
        "--budget", type=int, default=1024, help="keypoints per image (default: %(default)s)"
    )
    se.add_argument("--out", type=Path, required=True, metavar="OUT", help="output folder")
    se.add_argument(
        "--cameras",
        type=Path,
        default=None,
        metavar="MODEL",
        help="COLMAP text model (folder with cameras.txt and images.txt) giving intrinsics and "
        "poses",
    )
    se.add_argument(
        "--match",
        action="store_true",
        help="also write the matches and verified two-view geometries (colmap mapper runs on "
        "the database directly)",
    )
    se.add_argument(
        "--overlays", action="store_true", help="write OUT/overlays/<image>.png of each selection"
    )
    se.add_argument(
        "--max-candidates",
        type=int,
        default=8192,
        help="candidate pool per image: the strongest detections (default: %(default)s)",
    )
    se.add_argument(
        "--policy-module", action="append", default=[], metavar="FILE", help="as for `bench run`"
    )
    se.set_defaults(func=cmd_select)

    ex = sub.add_parser(
        "export",
        help="write a rendered scene as a dataset in the COLMAP layout (for `bench run --dataset`)",
        description="Render (or reuse) SCENE at --seed and write OUT/images/, the ground-truth "
        "model OUT/sparse/ (cameras.txt, images.txt, points3D.txt), the ground-truth point "
        "cloud OUT/ground_truth/points.ply and per-image OUT/ground_truth/<image>.npz (z, "
        "position).",
    )
    ex.add_argument("scene", metavar="SCENE", help="scene type (see `bench scenes`)")
    ex.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    ex.add_argument("--out", type=Path, required=True, metavar="DIR", help="dataset folder")
    add_config_args(ex, RenderConfig)
    _renders_arg(ex)
    ex.set_defaults(func=cmd_export)

    g = sub.add_parser(
        "gallery",
        help="render (or reuse) every scene and write a contact sheet of all views",
        description="One row per scene, one column per view, from the render cache "
        "(rendering what is missing).",
    )
    g.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(g, RenderConfig)
    _renders_arg(g)
    g.add_argument(
        "--out",
        type=Path,
        default=LATEST / "scenes.png",
        help=f"output image (default: ./{LATEST}/scenes.png; `bench publish` copies it)",
    )
    g.set_defaults(func=cmd_gallery)
    return p


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Python is running so that cleanup code runs (an interrupt)."""


def _terminate(signum, frame):
    raise Terminated


def _interrupted(e: BaseException) -> BaseException | None:
    """The interrupt behind an exception (a renderer wraps Ctrl-C in a RuntimeError)."""
    while e is not None:
        if isinstance(e, KeyboardInterrupt):
            return e
        e = e.__cause__ or e.__context__
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # our handler, not the one COLMAP's logging library installs (it aborts the process,
    # leaving lock files and half-written entries behind)
    signal.signal(signal.SIGTERM, _terminate)
    try:
        args.func(args)
    except BenchError as e:
        print(f"bench: error: {e}", file=sys.stderr)
        return 2
    except BaseException as e:
        stop = _interrupted(e)
        if stop is None:
            raise
        if isinstance(stop, Terminated):
            print("bench: terminated; finished work is kept", file=sys.stderr)
            return 143
        print("bench: interrupted; finished work is kept", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
