"""`bench train-matchability`: the `matchable` policy's models, learned from the exact
matchability labels of training renders (docs/matchability.md).

The label of a candidate of view i (`labels`): the number of other views j in which it is
matchable, that is, in which one candidate of j is both
* its ground-truth correspondence: its surface point, visible in j by the depth test
  (z within 1 % + 0.01), projects within `CORRESPONDENCE_PX` (3 px) of that candidate, in
  either direction (`SceneTruth.correspondences`, the oracle's and the metrics' test); and
* its tentative match between the whole pools: mutual nearest descriptors passing the
  ratio test at `backend.ratio` (0.8), as the back end matches.
No scale tolerance: the verification tests positions alone, and a descriptor match at the
right point is a correct match at any scale.

The model (`fit`): a gradient-boosted tree classifier of "matchable in at least one other
view" (label > 0) on the candidate's own-image `FEATURES` (scikit-learn's
`HistGradientBoostingClassifier`; no early stopping and a fixed random state, so one
command fits the same model), each view's candidates weighing 1 in all: the budget is
per view, and a scene type with larger pools would otherwise decide the model. One model per rendered scene type, trained on the other three, and
one on all four; the training seeds (100-102) are never evaluation seeds (the grid
refuses them). Photographs are never training data. Labels are training data only: the
policy at run time reads the model and its own view.

The record beside the model (`<out>.json`) holds, per held-out scene type, the precision
at B (the share of the selected candidates matchable in at least one other view) of the
model, of `octave-scale`'s and of `response`'s order, the features' permutation
importances, and one ablation per feature group.
"""

from __future__ import annotations

import json
import pickle
import time
from pathlib import Path

import numpy as np
import sklearn
from sklearn.ensemble import HistGradientBoostingClassifier
from sklearn.inspection import permutation_importance

from bench import BenchError
from bench.backend.matching import tentative_matches
from bench.codehash import code_hash
from bench.console import log, progress
from bench.evaluation.truth import CORRESPONDENCE_PX, scene_truth
from bench.files import atomic_path, write_text_atomic
from bench.frontend.matchability import EVERY_TYPE, FEATURES, features, predicted_order
from bench.frontend.policies import PolicyInput, octave_scale_policy, response_policy
from bench.frontend.stage import front_end
from bench.render.entry import render_scene
from bench.unit.config import RunConfig

PRECISION_BUDGETS = (128, 256, 512)
GROUPS = {
    "scale": ("log_sigma",),
    "contrast": ("log_response", "contrast"),
    "border": ("border_scale",),
    "repetition": ("twins", "distinct"),
}
"""The feature groups, each left out once (the ablation)."""
IMPORTANCE_SAMPLE = 20000
"""Held-out candidates the permutation importances are measured on (a fixed sample)."""


def labels(entry: Path, cfg: RunConfig, renders: Path, scene: str) -> list[tuple]:
    """Per view of a render entry: (its candidates' FEATURES, their labels (module
    docstring), its PolicyInput)."""
    fe = front_end(entry, cfg.detector, cfg.signals, renders / "frontend")
    cams, names = [v.camera for v in fe.views], [v.name for v in fe.views]
    truth = scene_truth(entry, cams, names, fe.pools)
    count = [np.zeros(len(p)) for p in fe.pools]
    for i in range(len(fe.pools)):
        for j in range(i + 1, len(fe.pools)):
            m = tentative_matches(
                fe.pools[i].descriptors, fe.pools[j].descriptors, cfg.backend.ratio
            )
            if len(m):
                ok = truth.correspondences(i, j, m[:, 0], m[:, 1])
                count[i][m[ok, 0]] += 1
                count[j][m[ok, 1]] += 1
    inputs = [PolicyInput(v, c, s, scene) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
    return [(features(inp), y, inp) for inp, y in zip(inputs, count)]


def fit(views: list[tuple], columns: list[int] | None = None) -> HistGradientBoostingClassifier:
    """The model of "matchable" on the features (`columns` of them; module docstring)."""
    X, y = _stack(views)
    weight = np.concatenate([np.full(len(v[1]), 1 / len(v[1])) for v in views])
    model = HistGradientBoostingClassifier(max_iter=200, early_stopping=False, random_state=0)
    return model.fit(X if columns is None else X[:, columns], y > 0, sample_weight=weight)


def precision_at(order: np.ndarray, y: np.ndarray, budget: int) -> float:
    """The share of the first `budget` of `order` matchable in at least one other view."""
    return float(np.mean(y[order[:budget]] > 0)) if len(order) else float("nan")


def _orders(model, views: list[tuple], columns: list[int]) -> dict[str, list]:
    out: dict[str, list] = {"matchable": [], "octave-scale": [], "response": []}
    rng = np.random.default_rng(0)
    for X, _, inp in views:
        out["matchable"].append(predicted_order(model, X[:, columns]))
        out["octave-scale"].append(octave_scale_policy(inp, len(X), rng, None))
        out["response"].append(response_policy(inp, len(X), rng, None))
    return out


def held_out_precision(model, views: list[tuple], columns: list[int]) -> dict[str, dict]:
    """Per order (the model's, `octave-scale`'s, `response`'s) and budget, the mean over
    the views of the precision at B."""
    orders = _orders(model, views, columns)
    return {
        name: {
            b: round(float(np.mean([precision_at(o, v[1], b) for o, v in zip(os_, views)])), 4)
            for b in PRECISION_BUDGETS
        }
        for name, os_ in orders.items()
    }


def _stack(views: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    return np.concatenate([v[0] for v in views]), np.concatenate([v[1] for v in views])


def train_matchability(
    scenes: list[str], seeds: list[int], cfg: RunConfig, renders: Path, out: Path
) -> dict:
    """Label the training renders, fit the models (one per held-out scene type and one on
    all), measure them on the held-out types, and write the model file and its record."""
    if len(set(scenes)) < 2:
        raise BenchError("training needs two scene types or more: each is held out in turn")
    t = time.perf_counter()
    data: dict[str, list[tuple]] = {s: [] for s in scenes}
    with progress("label", len(scenes) * len(seeds)) as bar:
        for scene in scenes:
            for seed in seeds:
                entry = render_scene(scene, seed, cfg.render, renders)
                data[scene] += labels(entry, cfg, renders, scene)
                bar.update()
    X, y = _stack([v for s in scenes for v in data[s]])
    if not y.any():
        raise BenchError("no training candidate is matchable anywhere; nothing to learn")
    every = list(range(len(FEATURES)))
    models, held_out = {EVERY_TYPE: fit([v for s in scenes for v in data[s]])}, {}
    with progress("fit", len(scenes)) as bar:
        for out_type in scenes:
            train = [v for s in scenes if s != out_type for v in data[s]]
            models[out_type] = fit(train)
            Xh, yh = _stack(data[out_type])
            sample = np.random.default_rng(0).permutation(len(yh))[:IMPORTANCE_SAMPLE]
            imp = permutation_importance(
                models[out_type],
                Xh[sample],
                yh[sample] > 0,
                n_repeats=3,
                random_state=0,
                scoring="roc_auc",
            )
            ablation = {}
            for group, names in GROUPS.items():
                keep = [k for k, f in enumerate(FEATURES) if f not in names]
                ablation[group] = held_out_precision(fit(train, keep), data[out_type], keep)[
                    "matchable"
                ]
            held_out[out_type] = {
                "candidates": int(len(yh)),
                "matchable": int((yh > 0).sum()),
                "precision": held_out_precision(models[out_type], data[out_type], every),
                "importance": dict(zip(FEATURES, np.round(imp.importances_mean, 5).tolist())),
                "without": ablation,
            }
            bar.update()
    record = {
        "model": "HistGradientBoostingClassifier of 'matchable in another view', views "
        "weighted alike (bench.harness.matchability)",
        "features": list(FEATURES),
        "seeds": list(seeds),
        "scenes": list(scenes),
        "samples": int(len(y)),
        "matchable": int((y > 0).sum()),
        "correspondence_px": CORRESPONDENCE_PX,
        "ratio": cfg.backend.ratio,
        "held_out": held_out,
        "sklearn": sklearn.__version__,
        "code": code_hash(("bench.harness.matchability",)),
        "settings": cfg.as_dict(),
        "seconds": round(time.perf_counter() - t, 1),
    }
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        tmp.write_bytes(pickle.dumps(record | {"models": models}))
    write_text_atomic(out.with_suffix(".json"), json.dumps(record, indent=1) + "\n")
    log(f"models of {len(y)} candidates ({record['matchable']} matchable) written to {out}")
    return record
