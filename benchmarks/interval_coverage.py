"""Coverage of the tables' 95% intervals at this grid's shape, by simulation.

Each simulated grid has S scenes (3 or 4) x N seeds (5: the sparse regime; `--seeds 2`:
the dense one) of paired differences A - B with a known mean: d = mu + a_s + e, a scene
effect a_s (drawn per grid) and noise e of one of several models (normal, unequal spread
per scene, skewed, heavy-tailed), or an mAA-like metric in [0, 1] (a method maps a cell or
not, all-or-nothing, and a mapped cell has a Beta-distributed mAA; A and B share the
cell's difficulty). The target is the mean over the grid's scenes of each scene's expected
difference (the tables' estimand: the mix of scenes is fixed). Per scene (N seeds) the
target is that scene's expected difference.

Measured: how often each method's 95% interval holds the target, over GRIDS grids per
model: the percentile bootstrap that resamples seeds within scenes (the method before
this benchmark), the stratified t-interval of `bench.report.stats`, and for comparison a
t-interval on the S scene means (S - 1 degrees of freedom: an interval for a new mix of
scenes, which is wider). A method is honest here when it covers 93-97%.

    .venv/bin/python benchmarks/interval_coverage.py [--grids 2000] [--seeds 5]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.special import stdtrit

from bench.report.stats import stratified_interval

RESAMPLES = 10_000


def percentile_bootstrap(d: np.ndarray, rng) -> tuple[float, float]:
    """The former method: seeds resampled within each scene (rows), percentile interval."""
    s, n = d.shape
    draws = np.stack([row[rng.integers(0, n, (RESAMPLES, n))].sum(1) for row in d]).sum(0)
    lo, hi = np.percentile(draws / d.size, [2.5, 97.5])
    return lo, hi


def scene_means_t(d: np.ndarray) -> tuple[float, float]:
    """A t-interval on the scene means, S - 1 degrees of freedom."""
    m = d.mean(1)
    half = stdtrit(len(m) - 1, 0.975) * m.std(ddof=1) / math.sqrt(len(m))
    return m.mean() - half, m.mean() + half


def stratified_t(d: np.ndarray) -> tuple[float, float]:
    _, lo, hi, _ = stratified_interval(d.ravel(), np.repeat(np.arange(len(d)), d.shape[1]))
    return lo, hi


def continuous(noise: str):
    """A model of differences: (draw(rng, S, N) -> (d of shape S x N, per-scene target))."""
    spreads = np.array([0.1, 0.5, 1.0, 2.0])

    def draw(rng, s, n):
        effect = 0.3 + rng.normal(0, 1.0, s)  # mu = 0.3, scene effects of sd 1
        sd = spreads[:s, None] if noise == "unequal" else 0.5
        if noise in ("normal", "unequal"):
            e = rng.normal(0, 1, (s, n))
        elif noise == "skewed":  # exponential (skewness 2), centred, sd 1
            e = rng.exponential(1, (s, n)) - 1
        elif noise == "very skewed":  # lognormal(0, 1) (skewness 6), centred, sd 1
            e = (rng.lognormal(0, 1, (s, n)) - math.exp(0.5)) / math.sqrt((math.e - 1) * math.e)
        else:  # heavy tails: Student t with 3 degrees of freedom, scaled to sd 1
            e = rng.standard_t(3, (s, n)) / math.sqrt(3)
        return effect[:, None] + sd * e, effect

    return draw


def maa(floor: bool):
    """mAA-like values in [0, 1] per method: a cell is mapped when its difficulty u is
    below the method's mapping rate in the scene, and a mapped cell's mAA is Beta(8, 2)
    (mean 0.8). `floor`: low mapping rates (most cells at 0, as the rendered grid had)."""

    def draw(rng, s, n):
        top = 0.35 if floor else 1.0
        p = rng.uniform(0, top, (2, s))  # mapping rates of A and B per scene
        u = rng.uniform(0, 1, (s, n))  # the cell's difficulty, shared by A and B
        a = (u < p[0][:, None]) * rng.beta(8, 2, (s, n))
        b = (u < p[1][:, None]) * rng.beta(8, 2, (s, n))
        return a - b, 0.8 * (p[0] - p[1])

    return draw


MODELS = {
    "normal": continuous("normal"),
    "unequal spread per scene": continuous("unequal"),
    "skewed (exponential)": continuous("skewed"),
    "very skewed (lognormal)": continuous("very skewed"),
    "heavy-tailed (t, 3 df)": continuous("heavy"),
    "mAA in [0, 1]": maa(floor=False),
    "mAA, mostly 0": maa(floor=True),
}


METHODS = {
    "pooled bootstrap": (percentile_bootstrap, "pooled"),
    "pooled strat-t": (lambda d, rng: stratified_t(d), "pooled"),
    "pooled scene-t": (lambda d, rng: scene_means_t(d), "pooled"),
    "scene bootstrap": (percentile_bootstrap, "scene"),
    "scene t": (lambda d, rng: stratified_t(d), "scene"),
}
"""Each method and whether it is applied to the grid (`pooled`) or to its first scene."""


def coverage(
    draw, scenes: int, seeds: int, grids: int, seed: int
) -> dict[str, tuple[float, float]]:
    """Per method: (% of the intervals that hold the target, % of grids with no interval)."""
    rng = np.random.default_rng(seed)
    hits, missing = dict.fromkeys(METHODS, 0), dict.fromkeys(METHODS, 0)
    for _ in range(grids):
        d, per_scene = draw(rng, scenes, seeds)
        for name, (method, scope) in METHODS.items():
            data, target = (d, per_scene.mean()) if scope == "pooled" else (d[:1], per_scene[0])
            lo, hi = method(data, rng)
            if math.isnan(lo):
                missing[name] += 1
            else:
                hits[name] += lo <= target <= hi
    return {
        k: (100 * hits[k] / max(grids - missing[k], 1), 100 * missing[k] / grids) for k in METHODS
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grids", type=int, default=2000)
    parser.add_argument("--seeds", type=int, default=5, help="seeds a scene (at least 2)")
    args = parser.parse_args()
    if args.seeds < 2:
        parser.error("--seeds: at least 2 (one seed a scene gives no interval)")
    print(
        f"coverage of the 95% interval, % of the intervals given ({args.grids} grids a row, "
        f"{args.seeds} seeds a scene); in brackets the % of grids given no interval (no spread)"
    )
    print(f"{'model':28s} S  " + "".join(f"{k:>21s}" for k in METHODS))
    for scenes in (3, 4):
        for i, (name, draw) in enumerate(MODELS.items()):
            row = coverage(draw, scenes, args.seeds, args.grids, seed=100 * scenes + i)
            cells = [f"{c:.1f}" + (f" ({m:.0f})" if m else "") for c, m in row.values()]
            print(f"{name:28s} {scenes}  " + "".join(f"{c:>21s}" for c in cells))


if __name__ == "__main__":
    main()
