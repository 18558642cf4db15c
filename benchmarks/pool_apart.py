"""The small-budget sfm gap between an own-image policy and `colmap-b`, taken apart (issue
53): the order the policy keeps candidates in, the pool's detector, its descriptor and the
matcher, each swapped on its own.

Per render entry and budget, the sfm mAA (multiview; the evaluation's truth, read here as
evaluation only) and the verified matches of five variants:

* `policy`: the policy's keypoints from the candidate pool (OpenCV's SIFT), matched by the
  policies' back end: its published row;
* `policy-root`: the same keypoints, their descriptors L1-root normalised (RootSIFT, what
  COLMAP's matcher compares) before the same back end;
* `colmap-kp-cv`: `colmap-b`'s keypoints (COLMAP's SIFT, B largest scales), described by
  OpenCV's SIFT at COLMAP's location, scale and orientation (the orientation's sign is the
  pool's convention: the sign with the more verified matches), then RootSIFT, same back end;
* `colmap-kp`: `colmap-b`'s keypoints and COLMAP's own descriptors, same back end;
* `colmap-b`: the stock peer (COLMAP's matcher and verification), its published row.

And per view, the share of `colmap-b`'s keypoints with a pool twin (within 1.5 px, scale
within 1.5x) and the share whose twin the policy keeps. One process; prints the table and
paired means; `--out` gets the per-cell CSV (temporary name, then renamed).

    PYTHONPATH=. .venv/bin/python benchmarks/pool_apart.py --scenes facade --seeds 0-4 \
        --budgets 128 --out /tmp/pool_apart.csv
    PYTHONPATH=. .venv/bin/python benchmarks/pool_apart.py --views 21 --seeds 0,1 \
        --renders DENSE_RENDERS --budgets 128 --out /tmp/pool_apart_dense.csv
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

import bench.harness.declared  # noqa: F401 (every method, as `bench run` has them)
from bench import BenchError
from bench.backend.matching import match_and_verify
from bench.backend.peers import COLMAP_SIFT, keypoint_scales, peer_extraction, run_peer
from bench.backend.reconstruction import mapping_task
from bench.cli.common import parse_list
from bench.evaluation.truth import scene_truth
from bench.files import atomic_path
from bench.frontend.geometry import IMAGES
from bench.frontend.policies import PolicyInput
from bench.frontend.selection import select_views
from bench.frontend.stage import front_end
from bench.frontend.views import Source, load_views
from bench.harness.config import RunConfig
from bench.harness.tasks import TASK_RUNNERS
from bench.render.entry import render_scene
from bench.scenes.spec import scene_names

VARIANTS = ("policy", "policy-root", "colmap-kp-cv", "colmap-kp", "colmap-b")
TWIN_PX, TWIN_SCALE = 1.5, 1.5


def root_sift(desc: np.ndarray) -> np.ndarray:
    """RootSIFT (Arandjelovic and Zisserman 2012; COLMAP's L1_ROOT): the square root of
    the L1-normalised descriptor, which has unit L2 length."""
    d = np.abs(np.asarray(desc, np.float64))
    return np.sqrt(d / np.maximum(d.sum(1, keepdims=True), 1e-12)).astype(np.float32)


def opencv_at(gray: np.ndarray, keypoints: np.ndarray, sign: int) -> np.ndarray:
    """OpenCV's SIFT descriptors at COLMAP's keypoints (x, y and the affine shape's scale
    and orientation; COLMAP's pixel convention, as the pool's)."""
    k = np.asarray(keypoints, np.float64)
    scale = keypoint_scales(keypoints)
    angle = (sign * np.degrees(np.arctan2(k[:, 4], k[:, 2]))) % 360
    kps = [
        cv2.KeyPoint(float(x - 0.5), float(y - 0.5), float(2 * s), float(a))
        for (x, y), s, a in zip(k[:, :2], scale, angle)
    ]
    out, desc = cv2.SIFT_create().compute(gray, kps)
    if len(out) != len(kps):
        raise BenchError("OpenCV dropped keypoints while describing COLMAP's")
    return desc


def measure(entry: Path, cfg: RunConfig, renders: Path, policy: str, budgets) -> list[dict]:
    fe = front_end(entry, cfg.detector, cfg.signals, renders / "frontend", IMAGES)
    names, cams = [v.name for v in fe.views], [v.camera for v in fe.views]
    image_dir = Source.of(entry).images
    truth = scene_truth(entry, [v.camera for v in load_views(entry)], names, fe.pools)
    inputs = [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
    sfm = TASK_RUNNERS["sfm"]

    def score(model) -> float:
        return 0.0 if model is None else sfm.evaluate(truth, model, names, "multiview", {})["maa"]

    def ours(xy, desc) -> tuple[float, int]:
        pairs = match_and_verify(cams, xy, desc, cfg.backend, cfg.detector.detector)[0]
        rec = mapping_task(image_dir, cams, names, xy, pairs, cfg.backend)
        return score(rec.model), sum(len(p.verified) for p in pairs)

    rows = []
    for budget in budgets:
        sel, _ = select_views(policy, inputs, budget, 0, cfg.policy_config(policy), None)
        pxy = [c.xy[s] for c, s in zip(fe.pools, sel)]
        pdesc = [c.descriptors[s] for c, s in zip(fe.pools, sel)]
        ex = peer_extraction(image_dir, names, cams, "colmap-b", budget, renders / COLMAP_SIFT)
        cxy = [e.keypoints[:, :2].astype(np.float64) for e in ex]
        out = {"policy": ours(pxy, pdesc), "policy-root": ours(pxy, [root_sift(d) for d in pdesc])}
        out["colmap-kp-cv"] = max(
            (
                ours(
                    cxy,
                    [root_sift(opencv_at(v.gray, e.keypoints, s)) for v, e in zip(fe.views, ex)],
                )
                for s in (1, -1)
            ),
            key=lambda r: r[1],
        )
        out["colmap-kp"] = ours(cxy, [root_sift(e.descriptors) for e in ex])
        run = run_peer(image_dir, names, cams, ex, cfg.backend, ["multiview"])
        out["colmap-b"] = (
            score(run.recs["multiview"].model),
            sum(len(p.verified) for p in run.pairs),
        )
        twin, kept = [], []
        for pool, s, e in zip(fe.pools, sel, ex):
            d, k = cKDTree(pool.xy).query(e.keypoints[:, :2])
            ratio = (pool.size[k] / 2) / keypoint_scales(e.keypoints)
            ok = (d <= TWIN_PX) & (ratio < TWIN_SCALE) & (ratio > 1 / TWIN_SCALE)
            twin.append(ok.mean())
            kept.append(np.isin(k[ok], s).sum() / len(k))
        row = {
            "entry": entry.name,
            "budget": budget,
            "twin": np.mean(twin),
            "twin_kept": np.mean(kept),
        }
        for name, (maa, verified) in out.items():
            row[name], row[f"{name}_verified"] = maa, verified
        rows.append(row)
        print(
            f"  {entry.name} {budget}: " + "  ".join(f"{n} {out[n][0]:.3f}" for n in VARIANTS),
            file=sys.stderr,
        )
    return rows


def summary(df: pd.DataFrame) -> str:
    """Mean mAA per budget and variant, and each swap's paired mean difference."""
    lines = []
    for budget, g in df.groupby("budget"):
        lines.append(
            f"budget {budget}, {len(g)} cells: "
            + ", ".join(f"{v} {g[v].mean():.3f}" for v in VARIANTS)
        )
        for a, b in zip(VARIANTS, VARIANTS[1:]):
            diff = g[b] - g[a]
            lines.append(
                f"  {b} - {a}: {diff.mean():+.3f} ({(diff > 0).sum()}/{(diff == 0).sum()}/{(diff < 0).sum()})"
            )
        lines.append(
            f"  twin {g.twin.mean():.2f}, twin kept by the policy {g.twin_kept.mean():.2f}"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(scene_names()))
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--views", type=int, default=6, help="views per path (the dense regime: 21)")
    ap.add_argument("--budgets", default="128")
    ap.add_argument("--policy", default="peak-scale", help="an own-image policy of the pool")
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    try:
        cfg = RunConfig()
        cfg = replace(cfg, render=replace(cfg.render, views=args.views))
        budgets = parse_list("--budgets", args.budgets, int)
        seeds = parse_list("--seeds", args.seeds, int)
        rows = []
        for scene in args.scenes.split(","):
            for seed in seeds:
                entry = render_scene(scene, seed, cfg.render, args.renders)
                rows += measure(entry, cfg, args.renders, args.policy, budgets)
    except BenchError as e:
        sys.exit(f"pool_apart: {e}")
    df = pd.DataFrame(rows)
    with atomic_path(args.out) as tmp:
        df.to_csv(tmp, index=False)
    print(summary(df))


if __name__ == "__main__":
    main()
