"""`bench train-matchability`: the `matchable` policy's models, from the renders' labels."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.cli.common import parse_list, renders_arg

HELP = "fit the `matchable` policy's models on the exact labels of training renders"
DESCRIPTION = (
    "Render (or reuse) every scene type at the training seeds, label every candidate by the "
    "number of other views it is matchable in (its ground-truth correspondence is its "
    "tentative match between the whole pools), and fit one model of that label on the "
    "candidate's own-image features per held-out scene type, and one on all types. Writes "
    "the model file and a JSON record beside it: the held-out precision at B against "
    "octave-scale's and response's order, the feature importances and one ablation per "
    "feature group. A benchmark whose seeds meet the training seeds is refused."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from bench.frontend.matchability import SHIPPED_MODEL
    from bench.scenes.spec import scene_names

    parser.add_argument("--seeds", default="100-102", help="training seeds (default: %(default)s)")
    parser.add_argument(
        "--scenes", default=",".join(scene_names()), help="scene types (default: %(default)s)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=SHIPPED_MODEL,
        help="model file (default: the one shipped with the package, %(default)s)",
    )
    renders_arg(parser)


def run(args: argparse.Namespace) -> None:
    from bench.harness.config import RunConfig
    from bench.harness.matchability import train_matchability
    from bench.scenes.spec import load_spec

    seeds = parse_list("--seeds", args.seeds, int, "100-119")
    scenes = parse_list("--scenes", args.scenes, str, "table,facade")
    for s in scenes:
        load_spec(s)
    record = train_matchability(list(scenes), list(seeds), RunConfig(), args.renders, args.out)
    for scene, r in record["held_out"].items():
        p = r["precision"]
        print(
            f"held out {scene:<11} precision at 256: matchable {p['matchable'][256]:.3f}  "
            f"octave-scale {p['octave-scale'][256]:.3f}  response {p['response'][256]:.3f}"
        )
