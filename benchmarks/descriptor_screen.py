"""The descriptor as a feature of own-image matchability, screened by correct matches at the
budget (issue 62; docs/matchability.md, "The descriptor, screened").

Why it could help where the six `FEATURES` did not: a point counts only where both views
keep it, so a selector's score must agree between views. Scale does (the same blob is
coarse in both); `border_scale` and `contrast` do not. The SIFT descriptor is built to be
the same in both views, and Hartmann, Havlena and Schindler (CVPR 2014) learned
matchability from it alone. 128 dimensions are too many for three training scene types, so
the descriptor enters as its first `COMPONENTS` principal components (fitted on the
training types' candidates only).

The label is the budget screen's (`budget_label_screen.budget_label`, K = 1,024: a correct
tentative match between the first 1,024 of two views by `octave-scale`'s order). Per
held-out scene type, gradient-boosted classifiers (the other three types, views weighted
alike, 100 iterations) on:

* `six+rank`: the six features and log2(rank in `octave-scale`'s order + 1), the best
  screened before;
* `six+rank+desc`: the same and the descriptor's components;
* `rank+desc`: scale rank and the components alone (what is view-consistent);
* `desc`: the components alone.

Each orders a view purely by its probability and as the blend log2(rank + 1) - L *
logit(p); each order is scored as `benchmarks/budget_matches.py` scores it (the correct
tentative matches between the top B of every pair of views, summed). Training seeds only
(100-102 by default; `--seeds 103,104` scores renders no choice saw, with the models
still trained on `--train-seeds`).

    .venv/bin/python benchmarks/descriptor_screen.py [--budgets 128,256,512]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from budget_label_screen import budget_label, fit
from budget_matches import correct_at, labelled_scene
from sklearn.decomposition import PCA

from bench.frontend.matchability import features
from bench.frontend.policies import octave_scale_policy
from bench.scenes.spec import scene_names
from bench.unit.config import RunConfig

COMPONENTS = 16
BLENDS = (0.1, 0.25, 0.5)
SETS = ("six+rank", "six+rank+desc", "rank+desc", "desc")


def cell_views(scene: str, seed: int, cfg: RunConfig, renders: Path):
    """One rendered cell: its front end, truth and per-view rows (features, descriptors,
    scale order and rank, the K = 1,024 label)."""
    fe, truth, inputs = labelled_scene(scene, seed, cfg, renders)
    orders = [octave_scale_policy(i, len(i.candidates), None, None) for i in inputs]
    ys = budget_label(fe, truth, orders, (1024,), cfg.backend.ratio)
    views = []
    for k, (inp, o, y) in enumerate(zip(inputs, orders, ys)):
        rank = np.empty(len(o))
        rank[o] = np.arange(len(o))
        six = np.column_stack([features(inp), np.log2(rank + 1)])
        desc = np.asarray(fe.pools[k].descriptors, np.float32)
        views.append({"six": six, "desc": desc, "order": o, "rank": rank, "y": y})
    return fe, truth, views


def design(v: dict, pca: PCA) -> dict[str, np.ndarray]:
    """The feature sets of one view."""
    d = pca.transform(v["desc"])
    return {
        "six+rank": v["six"],
        "six+rank+desc": np.column_stack([v["six"], d]),
        "rank+desc": np.column_stack([v["six"][:, -1], d]),
        "desc": d,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--budgets", default="128,256,512")
    ap.add_argument("--train-seeds", default="100,101,102")
    ap.add_argument("--seeds", default="", help="seeds scored (default: --train-seeds)")
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    args = ap.parse_args()
    cfg, budgets = RunConfig(), [int(b) for b in args.budgets.split(",")]
    train_seeds = [int(s) for s in args.train_seeds.split(",")]
    score_seeds = [int(s) for s in args.seeds.split(",")] if args.seeds else train_seeds
    t = time.perf_counter()
    train = {s: [cell_views(s, k, cfg, args.renders) for k in train_seeds] for s in scene_names()}
    scored = (
        train
        if score_seeds == train_seeds
        else {s: [cell_views(s, k, cfg, args.renders) for k in score_seeds] for s in scene_names()}
    )
    print(f"labelled in {time.perf_counter() - t:.0f} s")
    t = time.perf_counter()
    for scene in scene_names():
        views = [v for s, c in train.items() if s != scene for _, _, vs in c for v in vs]
        pca = PCA(COMPONENTS, random_state=0).fit(np.concatenate([v["desc"] for v in views]))
        for v in views:
            v.update(design(v, pca))
        models = {name: fit(views, None, name) for name in SETS}
        for _, _, vs in scored[scene]:
            for v in vs:
                v.update(design(v, pca))
                for name, m in models.items():
                    v[f"p {name}"] = m.predict_proba(v[name])[:, 1]
    print(f"fitted in {time.perf_counter() - t:.0f} s")

    def blend(v, lam, key):
        p = np.clip(v[key], 1e-4, 1 - 1e-4)
        return np.lexsort((v["rank"], np.log2(v["rank"] + 1) - lam * np.log(p / (1 - p))))

    orders_of = {"octave-scale": lambda v: v["order"]}
    for name in SETS:
        orders_of[f"{name} pure"] = lambda v, k=f"p {name}": np.lexsort((v["rank"], -v[k]))
        for lam in BLENDS:
            orders_of[f"{name} blend {lam:g}"] = lambda v, k=f"p {name}", lam=lam: blend(v, lam, k)
    for name, order in orders_of.items():
        total, row = np.zeros(len(budgets), int), []
        for scene, c in scored.items():
            n = np.zeros(len(budgets), int)
            for fe, truth, vs in c:
                ordered = [order(v) for v in vs]
                for k, b in enumerate(budgets):
                    n[k] += correct_at(fe, truth, ordered, b, cfg.backend.ratio)
            total += n
            row.append(f"{scene} {'/'.join(map(str, n))}")
        print(f"{name:24s}", "  ".join(row), f" all {'/'.join(map(str, total))}", flush=True)


if __name__ == "__main__":
    main()
