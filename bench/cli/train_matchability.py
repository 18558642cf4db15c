"""`bench train-matchability`: the `matchable` policy's models, from the renders' labels."""

from __future__ import annotations

import argparse

from bench.cli.common import training_args, training_grid

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

    training_args(parser, SHIPPED_MODEL, "model file")


def run(args: argparse.Namespace) -> None:
    from bench.harness.matchability import train_matchability
    from bench.unit.config import RunConfig

    scenes, seeds = training_grid(args)
    record = train_matchability(scenes, seeds, RunConfig(), args.renders, args.out)
    for scene, r in record["held_out"].items():
        p = r["precision"]
        print(
            f"held out {scene:<11} precision at 256: matchable {p['matchable'][256]:.3f}  "
            f"octave-scale {p['octave-scale'][256]:.3f}  response {p['response'][256]:.3f}"
        )
