"""`bench render SCENE`: one scene's views and ground truth into the render cache."""

from __future__ import annotations

import argparse

from bench.cli.common import add_config_args, render_config, renders_arg
from bench.render.config import VARIANTS, RenderConfig

HELP = f"render one scene ({RenderConfig.views} views by default + ground truth) into the cache"
DESCRIPTION = (
    "Path-trace the --views views of SCENE on its camera path with their ground-truth layers "
    "into renders/<scene>-s<seed>-<key>/ (each view also cached on its own, by its path "
    "position). A complete cached entry is reused unless --force."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="scene type (see `bench scenes`)")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    add_config_args(parser, RenderConfig, choices={"variant": VARIANTS})
    parser.add_argument(
        "--force", action="store_true", help="render again even if a complete entry exists"
    )
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.render.entry import render_scene

    cfg = render_config(args)
    print(render_scene(args.scene, args.seed, cfg, args.renders, force=args.force))
