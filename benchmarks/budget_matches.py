"""Correct matches at the budget, on the training renders: the offline check of an
own-image selector before a grid run (issue 62; docs/matchability.md, "At the budget").

Precision at B (`bench train-matchability`'s record) asks whether a selected candidate is
matchable against the other view's whole pool. A grid matches the selections: a point
counts only where both views selected it. This counts, per held-out scene type and B,
the tentative matches between the top-B of every pair of views (mutual nearest, ratio
0.8) that are ground-truth correspondences (`SceneTruth.correspondences`), for
`octave-scale`'s order and for each model file's order (the model that never saw the
type). Training seeds only (100-102): never the evaluation seeds.

    .venv/bin/python benchmarks/budget_matches.py [--models FILE ...] [--budgets 128,256,512]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.evaluation.truth import scene_truth
from bench.frontend.features import tentative_matches
from bench.frontend.matchability import features, model_for, predicted_order, read_models
from bench.frontend.policies import PolicyInput, octave_scale_policy
from bench.frontend.stage import front_end
from bench.render.entry import render_scene
from bench.scenes.spec import scene_names
from bench.unit.config import RunConfig


def correct_at(fe, truth, orders: list[np.ndarray], budget: int, ratio: float) -> int:
    """Correct tentative matches between the first `budget` of each view's order, summed
    over the pairs of views."""
    total = 0
    for i in range(len(orders)):
        for j in range(i + 1, len(orders)):
            a, b = orders[i][:budget], orders[j][:budget]
            m = tentative_matches(fe.pools[i].descriptors[a], fe.pools[j].descriptors[b], ratio)
            if len(m):
                total += int(truth.correspondences(i, j, a[m[:, 0]], b[m[:, 1]]).sum())
    return total


def labelled_scene(scene: str, seed: int, cfg: RunConfig, renders: Path):
    """A training render's front end, its truth and each view's policy input."""
    entry = render_scene(scene, seed, cfg.render, renders)
    fe = front_end(entry, cfg.detector, cfg.signals, renders / "frontend")
    truth = scene_truth(entry, [v.camera for v in fe.views], [v.name for v in fe.views], fe.pools)
    inputs = [PolicyInput(v, c, s, scene) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
    return fe, truth, inputs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--models", nargs="*", default=[""], help="model files ('' the shipped one)")
    ap.add_argument("--budgets", default="128,256,512")
    ap.add_argument("--seeds", default="100,101,102")
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    args = ap.parse_args()
    cfg, budgets = RunConfig(), [int(b) for b in args.budgets.split(",")]
    names = {"octave-scale": None} | {f"model {m or 'shipped'}": m for m in args.models}
    totals = {(n, b): 0 for n in names for b in budgets}
    for scene in scene_names():
        counts = {(n, b): 0 for n in names for b in budgets}
        for seed in (int(s) for s in args.seeds.split(",")):
            fe, truth, inputs = labelled_scene(scene, seed, cfg, args.renders)
            for name, file in names.items():
                if file is None:
                    orders = [octave_scale_policy(i, len(i.candidates), None, None) for i in inputs]
                else:
                    model = model_for(read_models(file), scene)
                    orders = [predicted_order(model, features(i)) for i in inputs]
                for b in budgets:
                    counts[name, b] += correct_at(fe, truth, orders, b, cfg.backend.ratio)
        for (name, b), v in counts.items():
            totals[name, b] += v
        print(scene, "  ".join(f"{n} B={b}: {v}" for (n, b), v in counts.items()))
    print("all  ", "  ".join(f"{n} B={b}: {v}" for (n, b), v in totals.items()))


if __name__ == "__main__":
    main()
