"""Front-end timings per view on a default render: candidates, detection, the geometry,
each signal, each policy's selection, and each policy's front end (detection, the signals
it reads with the geometry they need, its selection) relative to the texture-only one;
with the rig's poses (as the `tri` task) and with the geometry estimated from the images
(as the `sfm` task), and the ratio of the two. `adaptive-loop` is not here: its selection
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
from bench.frontend.policies import POLICIES, PolicyInput, select
from bench.frontend.selection import policy_rng
from bench.frontend.signals import TIMED, SignalConfig, compute_signals, seconds_of
from bench.frontend.views import load_views
from bench.render.config import RenderConfig
from bench.render.entry import render_scene
from bench.vocabulary import METHODS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="table")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--budget", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    views = load_views(render_scene(a.scene, a.seed, RenderConfig(), ROOT / "renders"))
    det = DetectorConfig()
    blind = [v.without_pose() for v in views]
    best: dict[str, dict[str, float]] = {"posed": {}, "pose-free": {}}
    for _ in range(a.repeats):  # best of N: the least disturbed measurement
        t = time.perf_counter()
        pools = [detect(v, det) for v in views]
        detect_s = time.perf_counter() - t
        for grant, vs in (("posed", views), ("pose-free", blind)):
            sigs, sig_s = compute_signals(vs, pools, det, SignalConfig())
            for k, v in {"detect": detect_s, **sig_s}.items():
                best[grant][k] = min(best[grant].get(k, np.inf), v)
    n = len(views)
    print(
        f"{a.scene} seed {a.seed}: candidates per view {[len(p) for p in pools]} (mean {np.mean([len(p) for p in pools]):.0f})"
    )
    print(f"  {'ms/view':<22} {'posed':>8} {'pose-free':>10}")
    for k in ("detect", *TIMED):
        print(
            f"  {k:<22} {1000 * best['posed'][k] / n:8.1f} {1000 * best['pose-free'][k] / n:10.1f}"
        )
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

    def front(policy: str, grant: str = "posed") -> float:
        b = best[grant]
        return 1000 * (b["detect"] + seconds_of(b, METHODS[policy].reads)) / n + sel_ms[policy]

    rho = [spearmanr(s.repeatability, s.repeatability_redetect)[0] for s in sigs]
    print(f"repeatability estimate vs re-detection: Spearman {np.mean(rho):.2f} (mean over views)")
    for policy in POLICIES:
        print(
            f"front end per view: {policy:<14} posed {front(policy):6.1f} ms "
            f"({front(policy) / front('texture'):.2f}x texture-only), pose-free "
            f"{front(policy, 'pose-free'):6.1f} ms ({front(policy, 'pose-free') / front(policy):.2f}x posed)"
        )


if __name__ == "__main__":
    main()
