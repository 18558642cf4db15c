"""Scoring speed (issue 29).

`points`: the point-to-surface distances of 1,000 points near a render entry's surface
(0-0.05 units) and 1,000 far from it (5-15 units), with one k-d tree over every sample (the
old way) and with `bench.evaluation.truth.Surface`; prints the seconds of each and whether
the distances are equal to the last bit.

`grid`: a small grid run with `bench run` (into RESULTS), then `bench run --reevaluate`;
prints the wall-clock of each and, from manifest.json, the seconds of the runs stage and of
the report, and the worker seconds of the scoring (evaluate, evaluate_matches) against those
of a unit's own stages (select, match, verify, task). `--code DIR` runs
another checkout of the code (e.g. the commit before this change) with this interpreter;
compare the two runs.csv files with benchmarks/compare_runs.py.

    .venv/bin/python benchmarks/scoring_speed.py points [--scene facade] [--renders DIR]
    .venv/bin/python benchmarks/scoring_speed.py grid --results DIR [--code DIR] \
        [-- bench run arguments: absolute paths, e.g. --renders /tmp/renders]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("what", choices=["points", "grid"])
ap.add_argument("--scene", default="facade")
ap.add_argument("--renders", default="renders")
ap.add_argument("--results", help="grid: the results folder (new, or one to re-score)")
ap.add_argument("--code", help="grid: a checkout of the code to run instead of this one")
argv = sys.argv[1:]
cut = argv.index("--") if "--" in argv else len(argv)
a = ap.parse_args(argv[:cut])
a.extra = argv[cut + 1 :]  # grid: arguments passed to `bench run`


def points() -> None:
    from scipy.spatial import cKDTree

    from bench.evaluation.layers import read_layers, surface_samples
    from bench.evaluation.truth import Surface
    from bench.render.config import RenderConfig
    from bench.render.entry import render_scene

    entry = render_scene(a.scene, 0, RenderConfig(), Path(a.renders))
    S = surface_samples(read_layers(entry))
    S = S.astype(np.float64)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    base = S[rng.integers(0, len(S), 1000)]
    t = time.perf_counter()
    tree = cKDTree(S)
    t_tree = time.perf_counter() - t
    t = time.perf_counter()
    surface = Surface(S)
    t_surface = time.perf_counter() - t
    print(f"{entry.name}: {len(S):,} surface samples, {len(surface.trees)} blocks")
    print(f"build: one k-d tree {t_tree:.3f} s, Surface {t_surface:.3f} s")
    for name, (lo, hi) in {"near": (0, 0.05), "far": (5, 15)}.items():
        X = base + d * rng.uniform(lo, hi, (1000, 1))
        t = time.perf_counter()
        old = tree.query(X)[0]
        t_old = time.perf_counter() - t
        t = time.perf_counter()
        new = surface.distances(X)
        t_new = time.perf_counter() - t
        print(
            f"1,000 {name} points ({lo}-{hi} units): one k-d tree {1000 * t_old:.1f} ms, "
            f"Surface {1000 * t_new:.1f} ms; equal to the last bit: {np.array_equal(old, new)}"
        )


def grid() -> None:
    env, code = dict(os.environ), Path(a.code or Path(__file__).parents[1]).resolve()
    env["PYTHONPATH"] = os.pathsep.join([str(code), env.get("PYTHONPATH", "")])
    results = Path(a.results).resolve()
    cmd = [sys.executable, "-m", "bench", "run", "--results", str(results), *a.extra]
    for label, more in (("run", []), ("--reevaluate", ["--reevaluate"])):
        t = time.perf_counter()
        subprocess.run(cmd + more, check=True, env=env, cwd=code, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - t
        rows = pd.read_csv(results / "runs.csv")
        s = json.loads((results / "manifest.json").read_text())["seconds"]
        unit = sum(s[k] for k in ("select", "match", "verify", "task"))
        print(
            f"{label}: {wall:.1f} s wall (runs stage {s['runs_wall']:.1f} s, report "
            f"{s['report']:.1f} s), {len(rows)} rows; worker seconds: scoring "
            f"{s['evaluate'] + s['evaluate_matches']:.1f}, a unit's stages (select, match, "
            f"verify, task) {unit:.1f}, of them tasks {s['task']:.1f}",
            flush=True,
        )


points() if a.what == "points" else grid()
