"""The small-budget gap, measured (issue 49): what `colmap-b` keeps and what each budgeted
policy keeps, and what becomes of it, by scale, response and image position.

For every kept keypoint of every view (the sfm task's selections: images and intrinsics
only), at each budget:

* `scale`: its detector scale sigma in px (OpenCV's size / 2; COLMAP's affine scale);
* `resp_pct`: the percentile of its response among the view's candidate pool (COLMAP's
  keypoints carry none: the nearest pool candidate's within 1 px, else NaN);
* `radius`: its distance from the image centre over the half diagonal;
* `repeated` (rendered scenes only: ground truth, evaluation side): of the other views
  where its ground-truth point is visible (depth test), the share holding a kept keypoint
  within 3 px of its projection;
* `verified`, `track_views`, `track3`, `registered`: whether it ends in a verified match,
  the number of views of its track (connected components of the verified matches; 1:
  none), whether that is 3+, and whether it ends in a point of the sfm model (multiview
  protocol);
* `correct`: whether it ends in a verified match within 4 px (the verification's
  threshold) of its epipolar line under the true poses (rendered and photographs alike).

Ground truth is read here as evaluation only; no policy sees it. One process, nothing
stored but the CSV of kept keypoints (`--out`), written to a temporary name then renamed.

    PYTHONPATH=. .venv/bin/python benchmarks/small_budget.py --scenes facade --seeds 0,1 \
        --budgets 128,256 --renders /work/renders-shared --out /tmp/small_budget.csv
    PYTHONPATH=. .venv/bin/python benchmarks/small_budget.py \
        --dataset /work/shared/datasets/strecha-herzjesu-p8 --budgets 128,256 ...
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

import bench.harness.declared  # noqa: F401 (every method, as `bench run` has them)
from bench import BenchError
from bench.backend.matching import match_and_verify
from bench.backend.peers import keypoint_scales, peer_extraction, run_peer
from bench.evaluation.layers import read_layers
from bench.evaluation.truth import CORRESPONDENCE_PX, _visible
from bench.frontend.geometry import IMAGES
from bench.frontend.policies import PolicyInput
from bench.frontend.selection import select_views
from bench.frontend.stage import front_end
from bench.frontend.views import Source, load_views
from bench.harness.config import RunConfig
from bench.harness.tasks import TASK_RUNNERS, Matched
from bench.render.entry import render_scene
from bench.vocabulary import METHODS, OWN_PIPELINE

POLICIES = ("cross-view", "track-first", "adaptive-fast", "response", "grid", "texture", "ssc")
PEERS = ("colmap-b", "colmap-soft-b")
EPIPOLAR_PX = 4.0
SCALE_BINS = [0, 2, 4, 8, 16, np.inf]
RESP_BINS = [0, 50, 75, 90, 100.001]
RADIUS_BINS = [0, 0.33, 0.66, 1.01]


def components(n_per_view: list[int], pairs) -> list[np.ndarray]:
    """Per view, the number of views of each kept keypoint's verified-match component."""
    offset = np.cumsum([0, *n_per_view])
    rows = [offset[p.i] + p.verified[:, 0] for p in pairs if len(p.verified)]
    cols = [offset[p.j] + p.verified[:, 1] for p in pairs if len(p.verified)]
    r = np.concatenate(rows) if rows else np.zeros(0, int)
    c = np.concatenate(cols) if cols else np.zeros(0, int)
    n = offset[-1]
    _, label = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)))
    view = np.repeat(np.arange(len(n_per_view)), n_per_view)
    span = pd.Series(view).groupby(label).nunique().to_numpy()[label]
    span[np.bincount(label, minlength=n)[label] == 1] = 1
    return [span[offset[v] : offset[v + 1]] for v in range(len(n_per_view))]


def fundamental(a, b) -> np.ndarray:
    """F with x_b^T F x_a = 0 for pixels of cameras a and b (true poses)."""
    R = b.R @ a.R.T
    t = b.t - R @ a.t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Ka = np.array([[a.fx, 0, a.cx], [0, a.fy, a.cy], [0, 0, 1]])
    Kb = np.array([[b.fx, 0, b.cx], [0, b.fy, b.cy], [0, 0, 1]])
    return np.linalg.inv(Kb).T @ tx @ R @ np.linalg.inv(Ka)


def epipolar_ok(F, xa, xb) -> np.ndarray:
    """Whether both points lie within EPIPOLAR_PX of the other's epipolar line."""
    ha, hb = np.c_[xa, np.ones(len(xa))], np.c_[xb, np.ones(len(xb))]
    la, lb = ha @ F.T, hb @ F  # lines in b, in a
    num = np.abs(np.sum(hb * la, 1))
    da = num / np.maximum(np.hypot(lb[:, 0], lb[:, 1]), 1e-12)
    db = num / np.maximum(np.hypot(la[:, 0], la[:, 1]), 1e-12)
    return (da < EPIPOLAR_PX) & (db < EPIPOLAR_PX)


def repeated(xy, gts, posed) -> list[np.ndarray]:
    """Per view, each kept keypoint's share of the other views (where its true point is
    visible) that hold a kept keypoint within CORRESPONDENCE_PX of its projection."""
    trees = [cKDTree(x) if len(x) else None for x in xy]
    out = []
    for i, x in enumerate(xy):
        gt = gts[i]
        col = np.clip(x[:, 0].astype(int), 0, gt.position.shape[1] - 1)
        row = np.clip(x[:, 1].astype(int), 0, gt.position.shape[0] - 1)
        X = gt.position[row, col].astype(np.float64)
        seen, hit = np.zeros(len(x)), np.zeros(len(x))
        for j in range(len(xy)):
            if j == i or trees[j] is None:
                continue
            uv, ok = _visible(np.nan_to_num(X), posed[j].camera, gts[j])
            ok &= np.isfinite(X).all(1)
            d = trees[j].query(np.nan_to_num(uv))[0]
            seen += ok
            hit += ok & (d <= CORRESPONDENCE_PX)
        with np.errstate(invalid="ignore"):
            out.append(hit / seen)
    return out


def kept_table(entry: Path, cfg: RunConfig, renders: Path, budgets, methods) -> pd.DataFrame:
    """One row per kept keypoint of every (method, budget) on one render entry or dataset."""
    fe = front_end(entry, cfg.detector, cfg.signals, renders / "frontend", IMAGES)
    posed = load_views(entry)
    names, cams = [v.name for v in fe.views], [v.camera for v in fe.views]
    image_dir = Source.of(entry).images
    gts = read_layers(entry) if Source.kind(entry) == "render" else None
    trees = [cKDTree(c.xy) for c in fe.pools]
    pct = [pd.Series(c.response).rank(pct=True).to_numpy() * 100 for c in fe.pools]
    inputs = [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
    det = cfg.detector.detector
    frames = []
    for budget in budgets:
        for method in methods:
            if method in PEERS:
                extracted = peer_extraction(image_dir, names, cams, method, budget)
                run = run_peer(image_dir, names, cams, extracted, cfg.backend, ["multiview"])
                shapes = [e.keypoints for e in extracted]  # with their affine shapes (N, 6)
                xy, pairs = run.keypoints, run.pairs
                scale = [keypoint_scales(s) for s in shapes]
                resp = []
                for v, x in enumerate(xy):
                    d, k = trees[v].query(x)
                    resp.append(np.where(d <= 1.0, pct[v][k], np.nan))
                model = run.recs["multiview"].model
            else:
                backend = cfg.backend
                if METHODS[method].matcher:
                    backend = replace(backend, matcher=METHODS[method].matcher)

                def match(sel, backend=backend):
                    xy = [c.xy[s] for c, s in zip(fe.pools, sel)]
                    desc = [c.descriptors[s] for c, s in zip(fe.pools, sel)]
                    return match_and_verify(cams, xy, desc, backend, det)[0]

                sel, _ = select_views(method, inputs, budget, 0, cfg.policy_config(method), match)
                xy = [c.xy[s] for c, s in zip(fe.pools, sel)]
                pairs = match(sel)
                scale = [c.size[s] / 2 for c, s in zip(fe.pools, sel)]
                resp = [p[s] for p, s in zip(pct, sel)]
                m = Matched(image_dir, cams, names, xy, pairs)
                model = TASK_RUNNERS["sfm"].reconstruct(m, backend, "multiview").model
            n = [len(x) for x in xy]
            verified = [np.zeros(k, bool) for k in n]
            correct = [np.zeros(k, bool) for k in n]
            for p in pairs:
                a, b = p.verified[:, 0], p.verified[:, 1]
                verified[p.i][a] = verified[p.j][b] = True
                ok = epipolar_ok(
                    fundamental(posed[p.i].camera, posed[p.j].camera), xy[p.i][a], xy[p.j][b]
                )
                correct[p.i][a[ok]] = correct[p.j][b[ok]] = True
            span = components(n, pairs)
            registered = [np.zeros(k, bool) for k in n]
            if model is not None:
                for img in model.images.values():
                    v = names.index(img.name)
                    registered[v] = np.array([p.has_point3D() for p in img.points2D], bool)
            rep = repeated(xy, gts, posed) if gts is not None else [np.full(k, np.nan) for k in n]
            for v in range(len(xy)):
                cam = cams[v]
                r = np.hypot(xy[v][:, 0] - cam.width / 2, xy[v][:, 1] - cam.height / 2)
                frames.append(
                    pd.DataFrame(
                        {
                            "method": method,
                            "budget": budget,
                            "view": v,
                            "scale": scale[v],
                            "resp_pct": resp[v],
                            "radius": r / np.hypot(cam.width, cam.height) * 2,
                            "repeated": rep[v],
                            "verified": verified[v],
                            "correct": correct[v],
                            "track_views": span[v],
                            "track3": span[v] >= 3,
                            "registered": registered[v],
                        }
                    )
                )
            print(f"  {entry.name} {method} {budget}: {sum(n)} kept", file=sys.stderr)
    return pd.concat(frames, ignore_index=True)


OUTCOMES = ["repeated", "verified", "correct", "track3", "registered"]


def summary(df: pd.DataFrame) -> str:
    """Mean outcome per method and budget, then per scale, response and position bin."""
    out = []
    g = df.groupby(["budget", "method"], sort=True)
    head = g[OUTCOMES].mean().round(3)
    views = df.groupby(["budget", "method"])[["scene", "seed", "view"]].apply(
        lambda x: len(x.drop_duplicates())
    )
    head.insert(0, "per_view", (g.size() / views).round(1))
    head.insert(2, "track_views", g["track_views"].mean().round(2))
    head.insert(1, "scale_med", g["scale"].median().round(2))
    out.append("overall (share of kept keypoints):\n" + head.to_string())
    for col, bins in (("scale", SCALE_BINS), ("resp_pct", RESP_BINS), ("radius", RADIUS_BINS)):
        binned = pd.cut(df[col], bins, right=False)
        share = (
            df.groupby(["budget", "method"])[col]
            .apply(
                lambda s, bins=bins: (
                    pd.cut(s, bins, right=False).value_counts(normalize=True).sort_index()
                )
            )
            .unstack()
            .round(2)
        )
        out.append(f"share of kept keypoints by {col}:\n" + share.to_string())
        for what in ("repeated", "registered"):
            t = df.groupby(["budget", "method", binned], observed=True)[what].mean().unstack()
            out.append(f"{what} by {col}:\n" + t.round(2).to_string())
    return "\n\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="facade")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--dataset", type=Path, action="append", default=[])
    ap.add_argument("--budgets", default="128,256")
    ap.add_argument("--methods", default=",".join((*PEERS, *POLICIES)))
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    try:
        budgets = [int(b) for b in args.budgets.split(",")]
        seeds = [int(s) for s in args.seeds.split(",")]
    except ValueError:
        sys.exit("small_budget: --budgets and --seeds are comma-separated integers")
    methods = args.methods.split(",")
    bad = [
        m
        for m in methods
        if m not in METHODS or (m not in PEERS and METHODS[m].kind == OWN_PIPELINE)
    ]
    if bad:
        print(f"small_budget: unknown method {bad[0]!r}", file=sys.stderr)
        sys.exit(2)
    cfg = RunConfig()
    frames = []
    try:
        units = [] if args.dataset else [(s, d) for s in args.scenes.split(",") for d in seeds]
        for scene, seed in units:
            entry = render_scene(scene, seed, cfg.render, args.renders)
            frames.append(
                kept_table(entry, cfg, args.renders, budgets, methods).assign(
                    scene=scene, seed=seed
                )
            )
        for ds in args.dataset:
            dcfg = replace(cfg, render=None)
            frames.append(
                kept_table(ds, dcfg, args.renders, budgets, methods).assign(scene=ds.name, seed=0)
            )
    except BenchError as e:
        print(f"small_budget: {e}", file=sys.stderr)
        sys.exit(2)
    df = pd.concat(frames, ignore_index=True)
    tmp = args.out.with_name(args.out.name + ".tmp")
    df.to_csv(tmp, index=False)
    tmp.rename(args.out)
    print(summary(df))


if __name__ == "__main__":
    main()
