"""The `bench` command line: scenes, render, run, plot."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from bench import ROOT, BenchError
from bench.config import QUICK_RENDER, VARIANTS, RenderConfig, field_docs
from bench.features import DETECTORS, DetectorConfig
from bench.policies import PolicyConfig


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of the CLI."""

    def error(self, message: str):
        self.exit(2, f"bench: error: {message} (see `{self.prog} --help`)\n")


def add_config_args(parser: argparse.ArgumentParser, cls: type) -> None:
    """One `--option` per dataclass field, its docstring as help and its default shown."""
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        kwargs = {
            "type": type(f.default),
            "default": f.default,
            "help": f"{docs.get(f.name, '')} (default: %(default)s)",
        }
        if f.name == "variant":
            kwargs["choices"] = VARIANTS
        parser.add_argument("--" + f.name.replace("_", "-"), dest=f.name, **kwargs)


def config_from_args(cls: type, args: argparse.Namespace):
    return cls(
        **{f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if hasattr(args, f.name)}
    )


def cmd_scenes(args: argparse.Namespace) -> None:
    from bench.scene import load_spec, scene_names

    for name in scene_names():
        spec = load_spec(name)
        print(f"{name}: {spec.description}")
        for k, v in spec.params.items():
            print(f"    {k} = {v!r:<10} {spec.docs.get(k, '')}")


def cmd_render(args: argparse.Namespace) -> None:
    from bench.render import render_scene

    cfg = config_from_args(RenderConfig, args).validate()
    entry = render_scene(args.scene, args.seed, cfg, args.renders, force=args.force)
    print(entry)


def cmd_gallery(args: argparse.Namespace) -> None:
    from bench.gallery import write_gallery
    from bench.render import render_scene
    from bench.scene import scene_names

    cfg = config_from_args(RenderConfig, args).validate()
    entries = {name: render_scene(name, args.seed, cfg, args.renders) for name in scene_names()}
    print(write_gallery(entries, args.out))


def _numbers(text: str, kind: type, what: str) -> tuple:
    """A comma-separated list of numbers; one that does not parse is the one-line error `what`
    (their values are checked with the rest of the configuration)."""
    try:
        return tuple(kind(x) for x in text.split(","))
    except ValueError:
        raise BenchError(f"{what}, got {text!r}") from None


def cmd_run(args: argparse.Namespace) -> None:
    from bench.harness import BenchConfig, run_benchmark
    from bench.pipeline import RunConfig
    from bench.report import HEADLINE, table1

    render = QUICK_RENDER if args.quick else RenderConfig()
    overrides = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(RenderConfig)
        if getattr(args, f.name) is not None
    }
    render = dataclasses.replace(render, **overrides)
    run = RunConfig(
        render=render,
        detector=DetectorConfig(detector=args.detector),
        policy=PolicyConfig(
            weights=_numbers(
                args.weights, float, "weights must be five numbers w_t,w_r,w_q,w_p,w_a"
            )
        ),
    )
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 3)
    cfg = BenchConfig(
        tuple(args.scenes),
        seeds,
        tuple(args.policies),
        _numbers(args.budget, int, "budget must be positive integers like 256 or 128,256,512"),
        run,
    )
    df = run_benchmark(cfg, args.results, args.renders, overwrite=args.overwrite)
    t = table1(df)
    print(
        t[["strategy", "budget", "runs", *HEADLINE]].to_string(
            index=False, float_format=lambda x: f"{x:.3f}"
        )
    )


def cmd_plot(args: argparse.Namespace) -> None:
    from bench.report import load_runs, write_report

    write_report(load_runs(args.results / "runs.csv"), args.results, args.renders)
    print(f"tables and figures rewritten in {args.results}")


def _dir_arg(parser: argparse.ArgumentParser, name: str, what: str) -> None:
    parser.add_argument(
        f"--{name}", type=Path, default=ROOT / name, help=f"{what} (default: {name}/)"
    )


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="bench",
        description="Rendered-scene benchmark of keypoint selection policies for 3D reconstruction.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("scenes", help="list the scene types and their parameters")
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
    _dir_arg(r, "renders", "render cache directory")
    r.set_defaults(func=cmd_render)

    from bench.harness import DEFAULT_POLICIES
    from bench.scene import scene_names

    u = sub.add_parser(
        "run",
        help="run the full benchmark: every scene, seed, policy and budget; tables and figures",
        description="Run every (scene, seed, policy, budget) of the grid: render (cached), "
        "candidates and signals (cached), selection, COLMAP matching, verification and "
        "triangulation with the known poses, evaluation against ground truth. Rows go to "
        "RESULTS/runs.csv as they finish; an interrupted run resumes where it stopped. Then "
        "table1.csv, table2.csv, figure2.png, figure3.png/.pdf and manifest.json.",
    )
    u.add_argument(
        "--scenes",
        nargs="+",
        default=scene_names(),
        metavar="SCENE",
        help="scene types (default: all four)",
    )
    u.add_argument(
        "--policies",
        nargs="+",
        default=list(DEFAULT_POLICIES),
        metavar="POLICY",
        help="policies (default: %(default)s)",
    )
    u.add_argument(
        "--budget",
        default="256",
        help="features per view, or a comma-separated list (default: %(default)s)",
    )
    u.add_argument(
        "--seeds",
        type=int,
        default=None,
        help="seeds 0..N-1 per scene (default: 3, or 1 with --quick)",
    )
    u.add_argument(
        "--weights",
        default=",".join(str(w) for w in PolicyConfig().weights),
        help=f"{field_docs(PolicyConfig)['weights']} (default: %(default)s)",
    )
    u.add_argument("--quick", action="store_true", help="smoke run: tiny renders, one seed")
    u.add_argument(
        "--detector",
        default="sift",
        choices=DETECTORS,
        help="candidate detector (default: %(default)s)",
    )
    docs = field_docs(RenderConfig)
    for f in dataclasses.fields(RenderConfig):
        kind = {"choices": VARIANTS} if f.name == "variant" else {"type": type(f.default)}
        quick = getattr(QUICK_RENDER, f.name)
        u.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            default=None,
            **kind,
            help=f"{docs[f.name]} (default: {f.default}, or {quick} with --quick)",
        )
    _dir_arg(u, "results", "results directory")
    _dir_arg(u, "renders", "render cache directory")
    u.add_argument(
        "--overwrite",
        action="store_true",
        help="replace results of another configuration in RESULTS",
    )
    u.set_defaults(func=cmd_run)

    pl = sub.add_parser(
        "plot",
        help="rebuild the tables and figures from runs.csv (no rendering, no reconstruction)",
        description="Rewrite table1.csv, table2.csv, figure3.png/.pdf (and the budget figure) "
        "from RESULTS/runs.csv alone, and figure2.png from it plus the exported model and the "
        "cached render.",
    )
    _dir_arg(pl, "results", "results directory")
    _dir_arg(pl, "renders", "render cache directory")
    pl.set_defaults(func=cmd_plot)

    g = sub.add_parser(
        "gallery",
        help="render (or reuse) every scene and write a contact sheet of all views",
        description="One row per scene, one column per view, from the render cache "
        "(rendering what is missing).",
    )
    g.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(g, RenderConfig)
    _dir_arg(g, "renders", "render cache directory")
    g.add_argument(
        "--out",
        type=Path,
        default=ROOT / "results" / "scenes.png",
        help="output image (default: results/scenes.png)",
    )
    g.set_defaults(func=cmd_gallery)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except BenchError as e:
        print(f"bench: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bench: interrupted; finished work is kept", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
