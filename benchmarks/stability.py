"""Whether a rendered ranking survives renders that differ in their last bits (issue 47).

Every view PNG of a small sparse slice is copied with a seeded share of its 8-bit values
moved by one unit (+1 or -1, clipped to 0..255; the entry's record of sizes and checksums
rewritten), as another machine's renders differ. The slice is run on the renders and on
the perturbed copy (`bench run`'s grid: tri, sfm and pairs at one budget, multiview), each
under one or more back-end seeds (`backend.seed`: COLMAP's RANSAC, triangulator and mapper).
Printed per task: the share of rows whose headline metric is identical, Kendall's tau of
the methods' means (renders against perturbed), and where sfm moved: the units whose
registered views changed (all-or-nothing registration) against those whose mAA moved with
every view registered. With several seeds, the same taus of the cell means averaged over
the seeds (the lever "several mapper seeds per cell"), and the tau between two seeds on the
same renders (how much the seed alone moves a ranking).

    .venv/bin/python benchmarks/stability.py --scenes facade --seeds 0,1 \
        --renders renders --out /tmp/stability [--backend-seeds 0,1,2] [--share 0.5]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
import zlib
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from bench.binding import read_vocabulary
from bench.files import META, checksum, write_text_atomic
from bench.harness.config import RunConfig
from bench.harness.execute import Cluster
from bench.harness.grid import BenchConfig, RunOptions, run_benchmark, with_reference
from bench.render.entry import render_scene
from bench.report.power import tau
from bench.report.tables import headline_frame, solvable
from bench.results import Workspace

METHODS = (
    "random,texture,grid,response,ssc,quadtree,adaptive,adaptive-fast,cross-view,learned,"
    "adaptive-loop,colmap-b,colmap-soft-b"
)
METRICS = {"tri": "acc_completeness_pct", "sfm": "sfm_maa", "pairs": "pairs_auc_10"}


def perturbed_copy(entry: Path, out: Path, share: float) -> Path:
    """A copy of a render entry whose view PNGs have `share` of their 8-bit values moved
    by one unit (seeded by the file's name and the entry's), its record rewritten."""
    dest = out / entry.name
    if dest.is_dir():
        return dest
    tmp = out / f".tmp-{entry.name}"
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(entry, tmp)
    meta = json.loads((tmp / META).read_text())
    for png in sorted(tmp.glob("view_*.png")):
        img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        rng = np.random.default_rng(zlib.crc32(f"{entry.name}/{png.name}".encode()))
        moved = rng.random(img.shape) < share
        step = rng.choice(np.array([-1, 1], np.int16), img.shape)
        new = np.clip(img.astype(np.int16) + moved * step, 0, 255).astype(img.dtype)
        cv2.imwrite(str(png), new)
        meta["files"][png.name] = {"bytes": png.stat().st_size, "crc32": checksum(png)}
    write_text_atomic(tmp / META, json.dumps(meta, indent=1))
    tmp.rename(dest)
    return dest


def run_slice(args, renders: Path, seed: int, results: Path) -> pd.DataFrame:
    """The slice's headline frame (multiview) on `renders` under back-end seed `seed`."""
    run = RunConfig()
    run = replace(run, backend=replace(run.backend, seed=seed))
    tasks = ("tri", "sfm", "pairs")
    cfg = BenchConfig(
        scenes=tuple(args.scenes.split(",")),
        seeds=tuple(int(s) for s in args.seeds.split(",")),
        methods=with_reference(tuple(args.methods.split(",")), tasks),
        budgets=(args.budget,),
        tasks=tasks,
        protocols=("multiview",),
        run=run,
    )
    t = time.perf_counter()
    df = run_benchmark(cfg, Workspace(results, renders), RunOptions(cluster=Cluster(1)))
    print(f"{results.name}: {time.perf_counter() - t:.0f} s")
    vocab = read_vocabulary(results)
    return headline_frame(df, vocab), vocab


def cells(frame: pd.DataFrame, vocab, metric: str) -> pd.DataFrame:
    rows = solvable(frame, metric, vocab)
    rows = rows[rows["budget"] > 0]
    return rows.pivot_table(index=["scene", "seed"], columns="method", values=metric)


def compare(a: pd.DataFrame, b: pd.DataFrame) -> tuple[float, float]:
    """(share of identical cells, tau of the method means) of two cells x methods frames."""
    a, b = a.align(b, join="inner")
    same = float(np.mean(np.isclose(a.to_numpy(), b.to_numpy(), rtol=0, atol=1e-12)))
    return same, tau(a.mean(), b.mean())


def sfm_causes(base: pd.DataFrame, other: pd.DataFrame) -> str:
    """Of the sfm units whose mAA moved: how many changed their registered views."""
    key = ["scene", "seed", "method", "budget"]
    cols = ["sfm_maa", "sfm_registered_views"]
    m = base[key + cols].merge(other[key + cols], on=key, suffixes=("", "_p")).dropna()
    moved = ~np.isclose(m["sfm_maa"], m["sfm_maa_p"], rtol=0, atol=1e-12)
    reg = m["sfm_registered_views"] != m["sfm_registered_views_p"]
    d = (m["sfm_maa"] - m["sfm_maa_p"]).abs()
    return (
        f"sfm units: {int(moved.sum())} of {len(m)} moved; {int((moved & reg).sum())} changed "
        f"their registered views (mean |d mAA| {d[reg].mean() if reg.any() else 0:.3f}), "
        f"{int((moved & ~reg).sum())} moved with the same views (mean |d mAA| "
        f"{d[moved & ~reg].mean() if (moved & ~reg).any() else 0:.3f})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="facade")
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--methods", default=METHODS)
    ap.add_argument("--budget", type=int, default=256)
    ap.add_argument("--backend-seeds", default="0")
    ap.add_argument("--share", type=float, default=0.5, help="share of values moved by 1")
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    perturbed = args.out / "renders-perturbed"
    perturbed.mkdir(exist_ok=True)
    t = time.perf_counter()
    for scene in args.scenes.split(","):
        for seed in map(int, args.seeds.split(",")):
            entry = render_scene(scene, seed, RunConfig().render, args.renders)
            perturbed_copy(entry, perturbed, args.share)
    print(f"perturbed copies: {time.perf_counter() - t:.0f} s")
    frames = {}
    for s in map(int, args.backend_seeds.split(",")):
        for name, renders in (("renders", args.renders), ("perturbed", perturbed)):
            frames[name, s] = run_slice(args, renders, s, args.out / f"{name}-b{s}")
    seeds = sorted({s for _, s in frames})
    for task, metric in METRICS.items():
        per = {k: cells(f, v, metric) for k, (f, v) in frames.items()}
        for s in seeds:
            same, t = compare(per["renders", s], per["perturbed", s])
            print(f"{task} {metric}, seed {s}: identical cells {same:.0%}, tau {t:.2f}")
        if len(seeds) > 1:
            mean = {n: sum(per[n, s] for s in seeds) / len(seeds) for n in ("renders", "perturbed")}
            same, t = compare(mean["renders"], mean["perturbed"])
            print(f"{task} {metric}, mean of {len(seeds)} seeds: identical {same:.0%}, tau {t:.2f}")
            same, t = compare(per["renders", seeds[0]], per["renders", seeds[1]])
            print(f"{task} {metric}, seed {seeds[0]} vs {seeds[1]} (same renders): tau {t:.2f}")
    for s in seeds:
        print(f"seed {s}: " + sfm_causes(frames["renders", s][0], frames["perturbed", s][0]))


if __name__ == "__main__":
    main()
