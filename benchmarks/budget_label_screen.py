"""A label defined at the budget, screened by correct matches at the budget (issue 62;
docs/matchability.md, "A label at the budget").

The shipped label asks whether a candidate is matchable against the other view's whole
pool. This one asks whether it is a correct tentative match (mutual nearest, ratio 0.8,
`SceneTruth.correspondences`) between the top K of both views by `octave-scale`'s order,
the candidates that compete at a budget: positive where that holds in some other view for
K = 256, 512 or 1,024. Per held-out scene type, a gradient-boosted classifier of it on the
six `FEATURES` (trained on the other three types, views weighted alike, 100 iterations)
orders each view:

* `pure`: by its probability alone (model trained on every candidate);
* `blend L`: by log2(rank in `octave-scale`'s order + 1) - L * logit(p), the scale order
  re-ranked where the model is confident;
* `rerank 2B`: `octave-scale`'s first 2B re-ordered by p (model trained on each view's
  first 1,024 by scale);
* `K1024+rank blend L`: the blend with a second model, of the label at K = 1,024 alone,
  given log2(rank in `octave-scale`'s order + 1) as a seventh feature.

Each order is scored as `benchmarks/budget_matches.py` scores it: the correct tentative
matches between the top B of every pair of views, summed. Training seeds only (100-102):
never the evaluation seeds.

    .venv/bin/python benchmarks/budget_label_screen.py [--budgets 128,256,512]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from budget_matches import correct_at, labelled_scene
from sklearn.ensemble import HistGradientBoostingClassifier

from bench.frontend.features import tentative_matches
from bench.frontend.matchability import features
from bench.frontend.policies import octave_scale_policy
from bench.scenes.spec import scene_names
from bench.unit.config import RunConfig

LABEL_K = (256, 512, 1024)
TOP = 1024
BLENDS = (0.25, 0.5, 1.0)
RANK_BLENDS = (0.1, 0.25)


def budget_label(fe, truth, orders: list[np.ndarray], ks, ratio: float) -> list[np.ndarray]:
    """Per view: in how many (other view, K) its candidate is a correct tentative match
    between the first K of both views' orders."""
    y = [np.zeros(len(o)) for o in orders]
    for k in ks:
        for i in range(len(orders)):
            for j in range(i + 1, len(orders)):
                a, b = orders[i][:k], orders[j][:k]
                m = tentative_matches(fe.pools[i].descriptors[a], fe.pools[j].descriptors[b], ratio)
                if len(m):
                    ok = truth.correspondences(i, j, a[m[:, 0]], b[m[:, 1]])
                    y[i][a[m[ok, 0]]] += 1
                    y[j][b[m[ok, 1]]] += 1
    return y


def fit(
    views: list[dict], top: int | None, x: str = "X", y_: str = "y"
) -> HistGradientBoostingClassifier:
    """The classifier of label > 0, each view's rows weighing 1 in all."""
    X, y, w = [], [], []
    for v in views:
        rows = v["order"][:top] if top else np.arange(len(v[y_]))
        X.append(v[x][rows])
        y.append(v[y_][rows] > 0)
        w.append(np.full(len(rows), 1 / max(len(rows), 1)))
    model = HistGradientBoostingClassifier(max_iter=100, early_stopping=False, random_state=0)
    return model.fit(np.concatenate(X), np.concatenate(y), sample_weight=np.concatenate(w))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--budgets", default="128,256,512")
    ap.add_argument("--seeds", default="100,101,102")
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    args = ap.parse_args()
    cfg, budgets = RunConfig(), [int(b) for b in args.budgets.split(",")]
    t = time.perf_counter()
    cells: dict[str, list] = {s: [] for s in scene_names()}
    for scene in cells:
        for seed in (int(s) for s in args.seeds.split(",")):
            fe, truth, inputs = labelled_scene(scene, seed, cfg, args.renders)
            orders = [octave_scale_policy(i, len(i.candidates), None, None) for i in inputs]
            ys = budget_label(fe, truth, orders, LABEL_K, cfg.backend.ratio)
            y1024 = budget_label(fe, truth, orders, (1024,), cfg.backend.ratio)
            views = []
            for inp, o, y, y1 in zip(inputs, orders, ys, y1024):
                rank = np.empty(len(o))
                rank[o] = np.arange(len(o))
                X = features(inp)
                X_rank = np.column_stack([X, np.log2(rank + 1)])
                views.append({"X": X, "X_rank": X_rank, "order": o, "rank": rank, "y": y, "y1": y1})
            cells[scene].append((fe, truth, views))
    print(f"labelled in {time.perf_counter() - t:.0f} s")
    t = time.perf_counter()
    for scene in cells:
        train = [v for s, c in cells.items() if s != scene for _, _, vs in c for v in vs]
        pure, top = fit(train, None), fit(train, TOP)
        ranked = fit(train, None, "X_rank", "y1")
        for _, _, vs in cells[scene]:
            for v in vs:
                v["p"] = pure.predict_proba(v["X"])[:, 1]
                v["p_top"] = top.predict_proba(v["X"])[:, 1]
                v["p_rank"] = ranked.predict_proba(v["X_rank"])[:, 1]
    print(f"fitted in {time.perf_counter() - t:.0f} s")

    def blend(v, lam, key="p"):
        p = np.clip(v[key], 1e-4, 1 - 1e-4)
        return np.lexsort((v["rank"], np.log2(v["rank"] + 1) - lam * np.log(p / (1 - p))))

    def rerank(v, b):
        head = v["order"][: 2 * b]
        return head[np.lexsort((np.arange(len(head)), -v["p_top"][head]))]

    orders_of = {
        "octave-scale": lambda v, b: v["order"],
        "pure": lambda v, b: np.lexsort((v["rank"], -v["p"])),
        **{f"blend {lam:g}": (lambda v, b, lam=lam: blend(v, lam)) for lam in BLENDS},
        "rerank 2B": rerank,
        **{
            f"K1024+rank blend {lam:g}": (lambda v, b, lam=lam: blend(v, lam, "p_rank"))
            for lam in RANK_BLENDS
        },
    }
    total = {n: np.zeros(len(budgets), int) for n in orders_of}
    for name, order in orders_of.items():
        row = []
        for scene, c in cells.items():
            n = np.zeros(len(budgets), int)
            for fe, truth, vs in c:
                for k, b in enumerate(budgets):
                    n[k] += correct_at(fe, truth, [order(v, b) for v in vs], b, cfg.backend.ratio)
            total[name] += n
            row.append(f"{scene} {'/'.join(map(str, n))}")
        print(f"{name:22s}", "  ".join(row), f" all {'/'.join(map(str, total[name]))}")


if __name__ == "__main__":
    main()
