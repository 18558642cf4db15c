"""The own-image question (issue 53): is the renders' gap between `response` and `colmap-b`
the policies' or the renders'? The candidate pool's SIFT (OpenCV, `DetectorConfig`)
against COLMAP's own SIFT on the same images, rendered and photographed.

Per view, at each budget B: the scale sigma (px; OpenCV's size / 2, COLMAP's affine
scale) of the pool and of COLMAP's extraction (medians, and the share below 2 px), and
the median scale of what `response` (the pool's B strongest), `scale` (the pool's B
largest, `benchmarks/own_image_policies.py`) and `colmap-b` (COLMAP's B largest) keep.
Images only: no truth is read. Prints one line per source and budget (medians over
views) and writes the per-view table to `--out` (temporary name, then renamed).

    PYTHONPATH=. .venv/bin/python benchmarks/own_image_scales.py --renders /tmp/h53/renders \
        --dataset /work/shared/datasets/strecha-herzjesu-p8 --out /tmp/own_image_scales.csv
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from bench.backend.peers import keypoint_scales, peer_extraction
from bench.files import atomic_path
from bench.frontend.features import DetectorConfig, detect, strongest_first
from bench.frontend.views import Source, load_views


def measure(source: Path, budgets: list[int]) -> list[dict]:
    views = load_views(source)
    names, cams = [v.name for v in views], [v.camera for v in views]
    extracted = peer_extraction(Source.of(source).images, names, cams, "colmap", 0)
    colmap = [e.keypoints for e in extracted]
    out = []
    for v, kps in zip(views, colmap):
        pool = detect(v, DetectorConfig())
        s_pool, s_colmap = pool.size / 2, keypoint_scales(kps)
        by_scale = np.lexsort((np.arange(len(s_pool)), -pool.response, -s_pool))
        by_colmap = np.lexsort((np.arange(len(s_colmap)), -s_colmap))
        for b in budgets:
            out.append(
                {
                    "source": "/".join(source.parts[-2:]),
                    "view": v.name,
                    "budget": b,
                    "pool": len(s_pool),
                    "colmap": len(s_colmap),
                    "pool_median": np.median(s_pool),
                    "colmap_median": np.median(s_colmap),
                    "pool_below_2px": np.mean(s_pool < 2),
                    "colmap_below_2px": np.mean(s_colmap < 2),
                    "response_kept": np.median(s_pool[strongest_first(pool.response)[:b]]),
                    "scale_kept": np.median(s_pool[by_scale[:b]]),
                    "colmap_b_kept": np.median(s_colmap[by_colmap[:b]]),
                }
            )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--renders", type=Path, help="a renders folder: every entry in it")
    ap.add_argument("--dataset", type=Path, action="append", default=[])
    ap.add_argument("--budgets", default="128,256,512")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]
    found = args.renders.iterdir() if args.renders and args.renders.is_dir() else []
    entries = sorted(p for p in found if p.is_dir() and p.name[0] != "." and p.name != "views")
    sources = [*entries, *args.dataset]
    if not sources:
        print("own_image_scales: no render entry or dataset given", file=sys.stderr)
        return 2
    rows = [r for s in sources for r in measure(s, budgets)]
    table = pd.DataFrame(rows)
    with atomic_path(args.out) as tmp:
        table.to_csv(tmp, index=False)
    cols = [c for c in table.columns if c not in ("source", "view", "budget")]
    print(table.groupby(["source", "budget"])[cols].median().round(2).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
