"""`bench export SCENE`: a rendered scene as a dataset in the COLMAP layout."""

from __future__ import annotations

import argparse

from bench.cli.common import add_config_args, folder, render_config, renders_arg
from bench.render.config import VARIANTS, RenderConfig

HELP = "write a rendered scene as a dataset in the COLMAP layout (for `bench run --dataset`)"
DESCRIPTION = (
    "Render (or reuse) SCENE at --seed and write OUT/images/, the ground-truth model "
    "OUT/sparse/ (cameras.txt, images.txt, points3D.txt), the ground-truth point cloud "
    "OUT/ground_truth/points.ply and per-image OUT/ground_truth/<image>.npz (z, position)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="scene type (see `bench scenes`)")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    parser.add_argument("--out", type=folder, required=True, metavar="DIR", help="dataset folder")
    add_config_args(parser, RenderConfig, choices={"variant": VARIANTS})
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.evaluation.export import check_target, export_dataset
    from bench.render.entry import render_scene

    cfg = render_config(args)
    check_target(args.out)  # one line, before the renderer says which variant it uses
    print(export_dataset(render_scene(args.scene, args.seed, cfg, args.renders), args.out))
