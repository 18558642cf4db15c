"""Peak memory of one process working through every unit of one scene and seed (what a
Dask worker holds at most: one scene's front end and ground truth, plus one unit).

    .venv/bin/python benchmarks/worker_memory.py --scene vegetation --seed 0
"""

from __future__ import annotations

import argparse
import resource
import tempfile
from pathlib import Path

from bench import ROOT
from bench.harness.execute import Plan, Work, scene_task, unit_task
from bench.harness.grid import BenchConfig
from bench.render.entry import render_scene
from bench.results import Workspace

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("--scene", default="vegetation")
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()
cfg = BenchConfig(scenes=(a.scene,), seeds=(a.seed,))
renders = ROOT / "renders"
entry = render_scene(a.scene, a.seed, cfg.run.render, renders)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
work = {u: Work(tuple(cfg.jobs(u.method))) for u in cfg.units()}
plan = Plan({(a.scene, a.seed): entry}, work)
scene_task((a.scene, a.seed), entry, cfg.run, renders, plan)
with tempfile.TemporaryDirectory() as tmp:
    for unit in cfg.units():
        unit_task(unit, plan, cfg.run, Workspace(Path(tmp), renders))
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(
    f"{a.scene} seed {a.seed}: {len(cfg.units())} units; peak RSS {peak:.0f} MiB "
    f"({before:.0f} MiB after the render-cache check)"
)
