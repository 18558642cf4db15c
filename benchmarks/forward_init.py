"""What lets stock COLMAP (the `colmap` peer: every SIFT feature, exhaustive matching,
COLMAP's verification, the incremental mapper with known fixed intrinsics) map the default
bags of a forward capture (issue 63, item 5): its first pair's angle, or the bags' baseline.

For each dataset and each of its default bags (`bench.unit.bags.dataset_bags`: 6 views,
10 bags, seeds 0-9), the peer's database is built and matched once, exactly as the harness
does (`peer_extraction`, `run_peer`), and the mapper (`map_database`, the `multiview`
protocol) is run under each setting below; only `init_min_tri_angle` (COLMAP's 16 deg) and
`init_max_forward_motion` (COLMAP's 0.95: a first pair whose unit translation has
|t_z| >= 0.95, i.e. within 18 deg of the optical axis, is refused) of the mapper's options
change (`_map_once`: the package's mapper from one setting alone; since the package
adopted the fallback `16 else (2, fwd 1.0)` as `map_database`'s second start, the default row
here is COLMAP's first start alone). Note
that COLMAP's pipeline already relaxes a failed start by itself: with no model it halves
`init_min_num_inliers`, then the angle, twice (16 -> 8 -> 4 deg at 100 -> 50 -> 25
inliers), so "16" below already includes first-pair attempts at 8 and 4 deg.

Each bag is scored as the sfm task scores it (`bench.evaluation.poses.pose_metrics`):
registered views and pose mAA (1-10 deg); a bag is "mapped" when every view is registered
with mAA >= `REFERENCE_MIN_MAA` (the harness's `reference_maps` rule). The fallback rows
are derived, not run again (the mapper is seeded and single-threaded, so a rerun gives the
same model): the default's result where it registers 2 views or more (`map_database`
succeeds), else the lower setting's.

Beside the table, each bag's geometry from the dataset's ground-truth poses: the median
distance between consecutive views (in position order) and the bag's span, and for every
verified pair the inliers triangulated with the true poses (midpoint of the two rays):
their median depth and median triangulation angle, and |t_z| of the pair's unit
translation. "init-ok" counts the pairs that would pass COLMAP's first-pair test at the
true geometry (>= 100 inliers, |t_z| < 0.95, median angle > 16 deg), "fwd" the pairs that
fail |t_z| alone.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/forward_init.py \
        ../shared/datasets/kitti-seq2 ../shared/datasets/middlebury-temple-sparse \
        ../shared/datasets/middlebury-dino-sparse ../shared/datasets/strecha-herzjesu-p8 \
        --strided ../shared/datasets/kitti-seq2

(`--cache renders/colmap-sift`, the default, is the harness's extraction cache.) With
`--strided ../shared/datasets/kitti-seq2`, also bags of 6 frames every 1, 2, 4 and 8
frames from frames 0 and 10 (`--strides`, `--starts`): bags that span more baseline.
"""

from __future__ import annotations

import argparse
import time
from itertools import combinations
from pathlib import Path

import numpy as np

import bench.backend.peers as peers
import bench.backend.reconstruction as recon
from bench.backend.matching import BackendConfig
from bench.evaluation.poses import pose_metrics, registered_poses
from bench.frontend.colmap_model import read_model
from bench.frontend.views import Source
from bench.unit.bags import DEFAULT_COUNT, DEFAULT_SIZE, dataset_bags
from bench.vocabulary import REFERENCE_MIN_MAA, REFERENCE_PEER

SETTINGS = {  # name: (init_min_tri_angle, init_max_forward_motion)
    "16 (default)": (16.0, 0.95),
    "8": (8.0, 0.95),
    "4": (4.0, 0.95),
    "2": (2.0, 0.95),
    "16, fwd 1.0": (16.0, 1.0),
    "8, fwd 1.0": (8.0, 1.0),
    "4, fwd 1.0": (4.0, 1.0),
    "2, fwd 1.0": (2.0, 1.0),
}
DEFAULT = "16 (default)"
FALLBACKS = {
    "16 else 4": "4",
    "16 else 2": "2",
    "16 else (4, fwd 1.0)": "4, fwd 1.0",
    "16 else (2, fwd 1.0)": "2, fwd 1.0",
}
INIT_INLIERS, INIT_FORWARD, INIT_ANGLE = 100, 0.95, 16.0

_captured: list[dict] = []


def _map_once(database, cfg, protocol, angle, forward) -> recon.Reconstruction:
    """The mapper from one first-pair setting alone (`map_database` without its second
    start), as `map_database` scores it."""
    opts = recon.fixed_intrinsics_options(cfg, protocol)
    opts.mapper.init_min_tri_angle = angle
    opts.mapper.init_max_forward_motion = forward
    t = time.perf_counter()
    best = recon._incremental(database, opts)
    if isinstance(best, str):
        return recon.Reconstruction(None, best, time.perf_counter() - t)
    recon.drop_short_tracks(best, recon.PROTOCOLS[protocol])
    return recon.Reconstruction(best, None, time.perf_counter() - t)


def _map_all_settings(database, cfg, protocol):
    """In place of `run_peer`'s `map_database`: the mapper under every setting (captured),
    the default's result returned."""
    out = {}
    for name, (angle, forward) in SETTINGS.items():
        t = time.perf_counter()
        rec = _map_once(database, cfg, protocol, angle, forward)
        out[name] = (rec, time.perf_counter() - t)
    _captured.append(out)
    return out[DEFAULT][0]


peers.map_database = _map_all_settings


def pair_geometry(cams, keypoints, pairs):
    """Per verified pair, at the true poses: (inliers, |t_z|, baseline, median depth,
    median triangulation angle in degrees)."""
    rows = []
    for p in pairs:
        a, b = cams[p.i], cams[p.j]
        m = np.asarray(p.verified, np.int64).reshape(-1, 2)
        Rr = b.R @ a.R.T
        tr = b.t - Rr @ a.t
        tz = abs(tr[2]) / max(np.linalg.norm(tr), 1e-12)
        base = float(np.linalg.norm(a.center - b.center))
        if len(m) < 5:
            rows.append((len(m), tz, base, np.nan, np.nan))
            continue
        da, db = a.rays(keypoints[p.i][m[:, 0]]), b.rays(keypoints[p.j][m[:, 1]])
        ca, cb = a.center, b.center
        # midpoint of the closest points of the rays ca + s da, cb + u db
        w = ca - cb
        bb = (da * db).sum(1)
        d, e = da @ w, db @ w
        den = np.maximum(1 - bb**2, 1e-12)
        s, u = (bb * e - d) / den, (e - bb * d) / den
        X = (ca + s[:, None] * da + cb + u[:, None] * db) / 2
        ok = (s > 0) & (u > 0)
        if ok.sum() < 5:
            rows.append((len(m), tz, base, np.nan, np.nan))
            continue
        depth = a.to_camera(X[ok])[:, 2]
        ra, rb = X[ok] - ca, X[ok] - cb
        cos = (ra * rb).sum(1) / (np.linalg.norm(ra, axis=1) * np.linalg.norm(rb, axis=1))
        angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        rows.append((len(m), tz, base, float(np.median(depth)), float(np.median(angle))))
    return rows


def bag_geometry(cams, keypoints, pairs) -> dict:
    centres = np.array([c.center for c in cams])
    order = np.argsort(np.linalg.norm(centres - centres[0], axis=1))  # along the path
    steps = np.linalg.norm(np.diff(centres[order], axis=0), axis=1)
    span = max(
        np.linalg.norm(centres[i] - centres[j]) for i, j in combinations(range(len(cams)), 2)
    )
    g = pair_geometry(cams, keypoints, pairs)
    depth = [r[3] for r in g if np.isfinite(r[3])]
    angle = [r[4] for r in g if np.isfinite(r[4])]
    return {
        "step": float(np.median(steps)),
        "span": float(span),
        "depth": float(np.median(depth)) if depth else np.nan,
        "best_angle": float(max(angle)) if angle else np.nan,
        "init_ok": sum(
            r[0] >= INIT_INLIERS and r[1] < INIT_FORWARD and r[4] > INIT_ANGLE for r in g
        ),
        "fwd": sum(r[1] >= INIT_FORWARD for r in g),
        "pairs": len(g),
    }


def score(rec, names, cams, size) -> tuple[int, float, bool]:
    est = registered_poses(rec.model, {n: k for k, n in enumerate(names)})
    row, _ = pose_metrics(est, cams)
    n, maa = int(row["registered_views"]), float(row["maa"])
    return n, maa, n == size and maa >= REFERENCE_MIN_MAA


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("datasets", type=Path, nargs="+")
    ap.add_argument("--cache", type=Path, default=Path("renders") / peers.COLMAP_SIFT)
    ap.add_argument("--protocol", default="multiview")
    ap.add_argument(
        "--strided",
        type=Path,
        help="also a dataset's bags of 6 frames every --strides-th frame (in name order), "
        "starting at each of --starts: bags that span more baseline than the default's",
    )
    ap.add_argument("--strides", default="1,2,4,8")
    ap.add_argument("--starts", default="0,10")
    a = ap.parse_args()
    cfg = BackendConfig()
    start = time.perf_counter()
    table, geo_lines = [], []
    sets = [(f, f.name, dataset_bags(str(f), DEFAULT_SIZE, DEFAULT_COUNT)) for f in a.datasets]
    if a.strided:
        order = [n for n, _ in read_model(Source.of(a.strided).model)]
        for stride in map(int, a.strides.split(",")):
            bags = [
                " ".join(order[s0 : s0 + DEFAULT_SIZE * stride : stride])
                for s0 in map(int, a.starts.split(","))
                if s0 + (DEFAULT_SIZE - 1) * stride < len(order)
            ]
            if bags:
                sets.append((a.strided, f"{a.strided.name} stride {stride}", tuple(bags)))
    for folder, set_name, bags in sets:
        src = Source.of(folder)
        cam_of = dict(read_model(src.model))
        per = {s: [] for s in [*SETTINGS, *FALLBACKS]}
        geos = []
        for k, bag in enumerate(bags):
            names = bag.split()
            cams = [cam_of[n] for n in names]
            t = time.perf_counter()
            extracted = peers.peer_extraction(src.images, names, cams, REFERENCE_PEER, 0, a.cache)
            run = peers.run_peer(names, cams, extracted, cfg, [a.protocol])
            res = _captured.pop()
            scores = {s: score(r, names, cams, len(names)) for s, (r, _) in res.items()}
            for s in SETTINGS:
                per[s].append(scores[s])
            for fb, low in FALLBACKS.items():
                per[fb].append(
                    scores[DEFAULT] if res[DEFAULT][0].model is not None else scores[low]
                )
            geo = bag_geometry(cams, run.keypoints, run.pairs)
            geos.append(geo)
            print(
                f"{set_name} bag {k} [{bag}] {time.perf_counter() - t:.0f}s: "
                + "; ".join(f"{s} {n}/{m:.2f}" for s, (n, m, _) in scores.items())
                + f" | step {geo['step']:.2f} span {geo['span']:.2f} depth {geo['depth']:.2f} "
                f"best-angle {geo['best_angle']:.1f} init-ok {geo['init_ok']}/{geo['pairs']} "
                f"fwd {geo['fwd']}",
                flush=True,
            )
        for s, rows in per.items():
            n, m, ok = zip(*rows)
            table.append((set_name, s, np.mean(n), np.mean(m), sum(ok), len(rows)))
        med = {
            key: np.nanmedian([g[key] for g in geos])
            for key in ("step", "span", "depth", "best_angle")
        }
        geo_lines.append(
            f"{set_name:26} {med['step']:8.3f} {med['span']:8.3f} {med['depth']:8.3f} "
            f"{med['depth'] / med['step']:9.1f} {med['best_angle']:10.1f} "
            f"{np.mean([g['init_ok'] for g in geos]):8.1f} {np.mean([g['fwd'] for g in geos]):6.1f}"
            f" / {np.mean([g['pairs'] for g in geos]):.1f}"
        )
    print(f"\n{'set':26} {'setting':22} {'reg views':>9} {'mAA':>6} {'mapped':>7}")
    for name, s, n, m, ok, count in table:
        print(f"{name:26} {s:22} {n:9.1f} {m:6.3f} {ok:>3}/{count}")
    print(
        f"\n{'set (medians over bags)':26} {'step':>8} {'span':>8} {'depth':>8} {'depth/step':>9} "
        f"{'best angle':>10} {'init-ok':>8} {'fwd / verified pairs':>6}"
    )
    print("\n".join(geo_lines))
    print(f"\nwall time {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
