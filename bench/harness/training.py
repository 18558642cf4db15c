"""`bench train-weights`: the `learned` policy's weights, fitted on training seeds.

For every scene and training seed: the whole candidate pool is matched, verified and
triangulated with the known poses under the headline protocol (`tri`, `multiview`), and
each candidate is labelled 1 when it observes a reconstructed point within 0.10 scene units
of the ground-truth surface (the headline accuracy threshold), else 0. A logistic model
of that label on the five adaptive signals (L2-regularised, lambda = 1e-4) is fitted by
L-BFGS; its coefficients are the weights, its intercept is kept for the record only (a
ranking ignores it). Training reads the ground truth of the training seeds; the policy
at evaluation time reads only the weights file, and a benchmark whose seeds meet the
training seeds is refused (`BenchConfig.validate`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from bench import BenchError
from bench.backend.matching import match_and_verify
from bench.backend.reconstruction import triangulate
from bench.codehash import code_hash
from bench.console import log, progress
from bench.evaluation.metrics import point_error
from bench.evaluation.truth import scene_truth
from bench.files import write_text_atomic
from bench.frontend.policies import ADAPTIVE_SIGNALS, Weights
from bench.frontend.stage import front_end
from bench.render.entry import render_scene
from bench.unit.config import RunConfig

LABEL_TAU = 0.10
L2 = 1e-4
PAPER = {k: (-1 if k == "ambiguity" else 1) * getattr(Weights(), k) for k in ADAPTIVE_SIGNALS}
"""The paper's weights as coefficients of the score (ambiguity counts against)."""


def labelled_candidates(entry: Path, cfg: RunConfig, renders: Path) -> tuple[np.ndarray, ...]:
    """(signals (N, 5), labels (N,)) of every candidate of one render entry."""
    fe = front_end(entry, cfg.detector, cfg.signals, renders / "frontend")
    cams, names = [v.camera for v in fe.views], [v.name for v in fe.views]
    truth = scene_truth(entry, cams, names, fe.pools)
    xy = [c.xy for c in fe.pools]
    pairs, _ = match_and_verify(
        cams, xy, [c.descriptors for c in fe.pools], cfg.backend, cfg.detector.detector
    )
    model = triangulate(cams, names, xy, pairs, cfg.backend)
    ids = list(model.points3D)
    X = np.array([model.points3D[i].xyz for i in ids]).reshape(-1, 3)
    accurate = dict(zip(ids, point_error(X, truth.surface) < LABEL_TAU))
    feats, labels = [], []
    for k, (sig, cand) in enumerate(zip(fe.signals, fe.pools)):
        y = np.zeros(len(cand))
        for n, p in enumerate(model.images[k + 1].points2D):
            if p.has_point3D():
                y[n] = accurate[p.point3D_id]
        feats.append(np.stack([getattr(sig, s) for s in ADAPTIVE_SIGNALS], 1))
        labels.append(y)
    return np.concatenate(feats), np.concatenate(labels)


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = L2) -> tuple[np.ndarray, float]:
    """Coefficients and intercept minimising the mean log loss + l2/2 |w|^2."""

    def loss(theta):
        w, b = theta[:-1], theta[-1]
        z = X @ w + b
        p = 1 / (1 + np.exp(-z))
        value = np.mean(np.logaddexp(0, z) - y * z) + l2 / 2 * w @ w
        grad = np.r_[X.T @ (p - y) / len(y) + l2 * w, np.mean(p - y)]
        return value, grad

    res = minimize(loss, np.zeros(X.shape[1] + 1), jac=True, method="L-BFGS-B")
    if not res.success:
        raise BenchError(f"the logistic fit did not converge: {res.message}")
    return res.x[:-1], float(res.x[-1])


def train_weights(
    scenes: list[str], seeds: list[int], cfg: RunConfig, renders: Path, out: Path
) -> dict:
    """Fit and write the weights file (module docstring); returns its content."""
    t = time.perf_counter()
    feats, labels = [], []
    with progress("train", len(scenes) * len(seeds)) as bar:
        for scene in scenes:
            for seed in seeds:
                entry = render_scene(scene, seed, cfg.render, renders)
                X, y = labelled_candidates(entry, cfg, renders)
                feats.append(X)
                labels.append(y)
                bar.update()
    X, y = np.concatenate(feats), np.concatenate(labels)
    if y.min() == y.max():
        raise BenchError("every training candidate has the same label; nothing to learn")
    w, b = fit_logistic(X, y)
    content = {
        "model": "logistic regression of 'observes a multiview point within "
        f"{LABEL_TAU} of the surface' (whole pool matched and triangulated, known poses)",
        "weights": dict(zip(ADAPTIVE_SIGNALS, np.round(w, 6).tolist())),
        "intercept": round(b, 6),
        "paper_weights": PAPER,
        "seeds": list(seeds),
        "scenes": list(scenes),
        "samples": int(len(y)),
        "positives": int(y.sum()),
        "code": code_hash([labelled_candidates, fit_logistic]),
        "settings": cfg.as_dict(),
        "seconds": round(time.perf_counter() - t, 1),
    }
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(Path(out), json.dumps(content, indent=1) + "\n")
    log(f"weights of {len(y)} candidates ({int(y.sum())} positive) written to {out}")
    return content
