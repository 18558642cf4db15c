"""`bench train-weights`: the `learned` policy's weights, fitted on training seeds."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.cli.common import parse_list, renders_arg

HELP = "fit the `learned` policy's weights on training seeds"
DESCRIPTION = (
    "Render (or reuse) every scene at the training seeds, match and triangulate each whole "
    "candidate pool with the known poses, label every candidate by whether it observes a "
    "point within 0.10 of the ground-truth surface, and fit a logistic model of that label "
    "on the five adaptive signals. Writes the weights with their provenance (seeds, scenes, "
    "code hash, settings). A benchmark whose seeds meet the training seeds is refused."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from bench.frontend.policies import SHIPPED_WEIGHTS
    from bench.scenes.spec import scene_names

    parser.add_argument("--seeds", default="100-102", help="training seeds (default: %(default)s)")
    parser.add_argument(
        "--scenes", default=",".join(scene_names()), help="scene types (default: %(default)s)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=SHIPPED_WEIGHTS,
        help="weights file (default: the one shipped with the package, %(default)s)",
    )
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.harness.config import RunConfig
    from bench.harness.training import train_weights
    from bench.scenes.spec import load_spec

    seeds = parse_list("--seeds", args.seeds, int, "100-119")
    scenes = parse_list("--scenes", args.scenes, str, "table,facade")
    for s in scenes:
        load_spec(s)
    w = train_weights(list(scenes), list(seeds), RunConfig(), args.renders, args.out)
    for k, v in w["weights"].items():
        print(f"{k:<16} learned {v:+.3f}   paper {w['paper_weights'][k]:+.2f}")
