"""The `bench` command line: scenes, render, run, plot."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from bench import ROOT, BenchError
from bench.config import VARIANTS, RenderConfig, field_docs


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of the CLI."""

    def error(self, message: str):
        self.exit(2, f"bench: error: {message} (see `{self.prog} --help`)\n")


def add_config_args(parser: argparse.ArgumentParser, cls: type, skip=()) -> None:
    """One `--option` per dataclass field, its docstring as help and its default shown."""
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
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


def cmd_run(args: argparse.Namespace) -> None:
    from bench.render import render_scene
    from bench.scene import load_spec

    cfg = config_from_args(RenderConfig, args).validate()
    for name in args.scenes:
        load_spec(name)  # unknown names fail before any work
    for name in args.scenes:
        for seed in range(args.seeds):
            print(render_scene(name, seed, cfg, args.renders))


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
    r.add_argument(
        "--renders",
        type=Path,
        default=ROOT / "renders",
        help="render cache directory (default: renders/)",
    )
    r.set_defaults(func=cmd_render)

    from bench.scene import scene_names

    u = sub.add_parser(
        "run",
        help="run the benchmark (for now: render every scene and seed into the cache)",
        description="Render every (scene, seed) of the benchmark grid into the render cache.",
    )
    u.add_argument("--scenes", nargs="+", default=scene_names(), help="scene types (default: all)")
    u.add_argument(
        "--seeds", type=int, default=3, help="seeds 0..N-1 per scene (default: %(default)s)"
    )
    add_config_args(u, RenderConfig)
    u.add_argument(
        "--renders",
        type=Path,
        default=ROOT / "renders",
        help="render cache directory (default: renders/)",
    )
    u.set_defaults(func=cmd_run)

    g = sub.add_parser(
        "gallery",
        help="render (or reuse) every scene and write a contact sheet of all views",
        description="One row per scene, one column per view, from the render cache "
        "(rendering what is missing).",
    )
    g.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(g, RenderConfig)
    g.add_argument(
        "--renders",
        type=Path,
        default=ROOT / "renders",
        help="render cache directory (default: renders/)",
    )
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
