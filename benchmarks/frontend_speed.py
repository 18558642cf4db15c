"""Front-end timings per view on a default render: candidates, detection, each signal, each
policy's selection, and each policy's front end (detection, the signals it reads, its
selection) relative to the texture-only one. `adaptive-loop` is not here: its selection
includes matching rounds (see frontend_cost.csv of a benchmark run).

    .venv/bin/python benchmarks/frontend_speed.py [--scene table] [--seed 0] [--budget 256]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import spearmanr

from bench import ROOT
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.policies import POLICIES, SIGNALS_USED, PolicyInput, select
from bench.frontend.signals import SIGNALS, SignalConfig, compute_signals
from bench.frontend.views import load_views
from bench.harness.pipeline import policy_rng
from bench.render.config import RenderConfig
from bench.render.entry import render_scene


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="table")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--budget", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    views = load_views(render_scene(a.scene, a.seed, RenderConfig(), ROOT / "renders"))
    det = DetectorConfig()
    best = {}
    for _ in range(a.repeats):  # best of N: the least disturbed measurement
        t = time.perf_counter()
        pools = [detect(v, det) for v in views]
        detect_s = time.perf_counter() - t
        sigs, sig_s = compute_signals(views, pools, det, SignalConfig())
        for k, v in {"detect": detect_s, **sig_s}.items():
            best[k] = min(best.get(k, np.inf), v)
    n = len(views)
    print(
        f"{a.scene} seed {a.seed}: candidates per view {[len(p) for p in pools]} (mean {np.mean([len(p) for p in pools]):.0f})"
    )
    print(f"  detect          {1000 * best['detect'] / n:7.1f} ms/view")
    for s in SIGNALS:
        print(f"  {s:<15} {1000 * best[s] / n:7.1f} ms/view")
    sel_ms = {}
    for name in POLICIES:
        t = time.perf_counter()
        for _ in range(a.repeats):
            for v, c, s in zip(views, pools, sigs):
                select(
                    name,
                    PolicyInput(v, c, s),
                    a.budget,
                    policy_rng(a.seed, name, a.budget, v.index),
                )
        sel_ms[name] = 1000 * (time.perf_counter() - t) / (a.repeats * n)
        print(f"  select {name:<8} {sel_ms[name]:7.2f} ms/view")

    def front(policy: str) -> float:
        return (
            1000 * (best["detect"] + sum(best[s] for s in SIGNALS_USED[policy])) / n
            + sel_ms[policy]
        )

    rho = [spearmanr(s.repeatability, s.repeatability_redetect)[0] for s in sigs]
    print(f"repeatability estimate vs re-detection: Spearman {np.mean(rho):.2f} (mean over views)")
    for policy in POLICIES:
        print(
            f"front end per view: {policy:<18} {front(policy):6.1f} ms, "
            f"{front(policy) / front('texture'):.2f}x texture-only"
        )


if __name__ == "__main__":
    main()
