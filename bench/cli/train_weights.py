"""`bench train-weights`: the `learned` policy's weights, fitted on training seeds."""

from __future__ import annotations

import argparse

from bench.cli.common import training_args, training_grid

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

    training_args(parser, SHIPPED_WEIGHTS, "weights file")


def run(args: argparse.Namespace) -> None:
    from bench.harness.training import train_weights
    from bench.unit.config import RunConfig

    scenes, seeds = training_grid(args)
    w = train_weights(scenes, seeds, RunConfig(), args.renders, args.out)
    for k, v in w["weights"].items():
        print(f"{k:<16} learned {v:+.3f}   paper {w['paper_weights'][k]:+.2f}")
