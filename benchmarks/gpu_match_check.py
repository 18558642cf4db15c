"""Whether the GPU matcher (`bench.backend.gpu`) gives the CPU's tentative matches on real
SIFT descriptors, and how fast: the views of the render entries in a renders folder, every
pair of views of each entry, their first B candidates (a budget's worth) and all of them.

    .venv/bin/python benchmarks/gpu_match_check.py [--renders renders] [--entries 4] [--cpu]

Prints, per B: pairs compared, pairs the GPU decided (the others it leaves to the CPU,
near a tie), pairs whose matches differ from the CPU's (must be 0), and the milliseconds
per pair of the CPU matcher and of `bench.backend.matching.tentative_matches` (the GPU
where it decides, else the CPU). Exit 1 if any pair differs, 2 without a GPU or entries.
`--cpu` runs the check on CPU torch (a dry run of this script where no GPU is).
"""

from __future__ import annotations

import argparse
import sys
import time
from itertools import combinations
from pathlib import Path

import numpy as np

from bench.backend import gpu
from bench.backend.matching import tentative_matches
from bench.frontend import features
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.views import load_views

BUDGETS = (128, 256, 512, None)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    ap.add_argument("--entries", type=int, default=4, help="render entries to read")
    ap.add_argument("--ratio", type=float, default=0.8)
    ap.add_argument("--cpu", action="store_true", help="torch on the CPU (a dry run)")
    args = ap.parse_args()
    if args.cpu:
        import torch

        gpu.device = lambda: torch.device("cpu")  # what the back end's matcher then uses
    where = gpu.device()
    if where is None:
        print("gpu_match_check: no CUDA device (or no torch): nothing to check", file=sys.stderr)
        return 2
    entries = sorted(p.parent for p in args.renders.glob("*/meta.json"))[: args.entries]
    if not entries:
        print(f"gpu_match_check: no render entry in {args.renders}", file=sys.stderr)
        return 2
    pools = [[detect(v, DetectorConfig()).descriptors for v in load_views(e)] for e in entries]
    print(f"{len(entries)} entries, {sum(map(len, pools))} views on {where}")
    bad = 0
    for budget in BUDGETS:
        pairs = [(a[:budget], b[:budget]) for views in pools for a, b in combinations(views, 2)]
        decided = differ = 0
        for a, b in pairs:
            ref = features.tentative_matches(a, b, args.ratio)
            out = gpu.matches_on(a, b, args.ratio, where)
            if out is not None:
                decided += 1
                differ += not np.array_equal(out, ref)
        timing = {}
        for name, fn in (("cpu", features.tentative_matches), ("matcher", tentative_matches)):
            fn(*pairs[0], args.ratio)  # warm
            t = time.perf_counter()
            for a, b in pairs:
                fn(a, b, args.ratio)
            timing[name] = 1000 * (time.perf_counter() - t) / len(pairs)
        bad += differ
        print(
            f"B={budget or 'all'}: {len(pairs)} pairs, GPU decided {decided}, differ {differ}; "
            f"ms per pair: CPU {timing['cpu']:.2f}, matcher {timing['matcher']:.2f}"
        )
    print("identical" if not bad else f"{bad} pair(s) differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
