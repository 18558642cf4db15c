"""`bench gallery`: a contact sheet of every scene's views."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.cli.common import LATEST, add_config_args, render_config, renders_arg
from bench.render.config import VARIANTS, RenderConfig

HELP = "render (or reuse) every scene and write a contact sheet of all views"
DESCRIPTION = (
    "One row per scene, one column per view, from the render cache (rendering what is missing)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from bench.results import GALLERY

    parser.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(parser, RenderConfig, choices={"variant": VARIANTS})
    renders_arg(parser)
    parser.add_argument(
        "--out",
        type=Path,
        default=LATEST / GALLERY,
        help=f"output image (default: ./{LATEST}/{GALLERY}; `bench publish` copies it)",
    )


def run(args: argparse.Namespace) -> None:
    from bench.render.entry import render_scene
    from bench.render.gallery import write_gallery
    from bench.scenes.spec import scene_names

    cfg = render_config(args)
    entries = {name: render_scene(name, args.seed, cfg, args.renders) for name in scene_names()}
    print(write_gallery(entries, args.out))
