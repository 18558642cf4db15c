"""The next-views measurement (the nbv task, docs/protocol.md): every scene's 21-view path
with seeds 0-4, then the three shared real sets, each into its own results folder with
Table 3, `figure_views.png` and its page; the datasets' `transfer.csv` ranks the choosers
against the rendered folder. Prints each command's wall-clock time.

    .venv/bin/python benchmarks/nbv.py [--budget 128,256,512] [--seeds 0-4] [--workers 2]
        [--renders renders] [--results results] [--datasets ../shared/datasets] [--only renders|datasets]

Rendered scenes: `bench run --tasks nbv --protocols multiview` -> RESULTS/nbv/ (headline
protocol only: the twoview one doubles the reconstructions and is no headline). Datasets:
`bench run --dataset` of each shared set (templeSparseRing, dinoSparseRing, Herz-Jesu) with
`--set nbv.every=2` (initial capture: every second image, so 8 + 8 on the 16-view rings
and 4 + 4 on Herz-Jesu) -> RESULTS/nbv-datasets/, compared with RESULTS/nbv/ (`--rendered`).
The datasets have poses alone, so their scores are the sfm task's mAA and the oracle picks
by it.

Cost, from one measured path (table seed 0, 640x480, the three budgets, one worker on a
2-core machine shared with another run: 588 s cold, 149 s of it rendering the 21 views,
`oracle-view` 352 s of the 438 s of units; docs/protocol.md): renders, all budgets, two
workers, about 2.3 h cold (50 min of it rendering), 2 h with the sparse regime's views
rendered; `--budget 256` about 1.2 h cold. The datasets (three budgets, not measured):
about 40 min, most of it Herz-Jesu's 3072x2048 front ends of each capture. Measured at
`--budget 256` (two workers, commit e0c830d): renders 66.1 min (180 of the 420 views
rendered, the rest cached by both regimes' runs; the machine shared for about half of it),
datasets 6.0 min.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SETS = ("middlebury-temple-sparse", "middlebury-dino-sparse", "strecha-herzjesu-p8")

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("--budget", default="128,256,512", help="budgets per view (bench run --budget)")
ap.add_argument("--seeds", default="0-4", help="scene seeds of the rendered scenes")
ap.add_argument("--workers", default="2", help="Dask workers (bench run --workers)")
ap.add_argument("--renders", type=Path, default=ROOT / "renders", help="render cache")
ap.add_argument("--results", type=Path, default=ROOT / "results", help="where the folders go")
ap.add_argument(
    "--datasets", type=Path, default=ROOT.parent / "shared" / "datasets", help="the shared sets"
)
ap.add_argument("--only", choices=("renders", "datasets"), default=None, help="one half only")
a = ap.parse_args()
bench = Path(sys.executable).with_name("bench")
common = ["--tasks", "nbv", "--protocols", "multiview", "--budget", a.budget]
common += ["--workers", a.workers, "--renders", str(a.renders)]
rendered = a.results / "nbv"
runs = {
    "renders": ["--seeds", a.seeds, "--results", str(rendered)],
    "datasets": [
        *(arg for s in SETS for arg in ("--dataset", str(a.datasets / s))),
        *("--set", "nbv.every=2", "--rendered", str(rendered)),
        *("--results", str(a.results / "nbv-datasets")),
    ],
}
for name, args in runs.items():
    if a.only not in (None, name):
        continue
    t = time.perf_counter()
    subprocess.run([str(bench), "run", *common, *args], check=True)
    print(f"nbv on {name}: {(time.perf_counter() - t) / 60:.1f} min", flush=True)
