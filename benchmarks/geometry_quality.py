"""How good is the geometry the front end estimates from the images, for a first-pass size?

For render entries (default: every entry in renders/ at the default size), per first-pass
size: the pairs found to overlap (against the rig's overlap test), the median rotation
and translation-direction errors of the estimated relative poses against the rig's, the
seconds of the estimate per view, and the Spearman correlation of the pose-free parallax
and epipolar signals with the posed ones. The rig's poses are read here only to score.

    .venv/bin/python benchmarks/geometry_quality.py [--sizes 256,512,1024] [ENTRY ...]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from bench.frontend.features import DetectorConfig, detect
from bench.frontend.geometry import SignalConfig, image_geometry, rig_geometry
from bench.frontend.signals import compute_signals
from bench.frontend.views import load_views


def angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("entries", nargs="*", type=Path)
    ap.add_argument("--sizes", default="256,512,1024")
    args = ap.parse_args()
    entries = args.entries or sorted(
        p for p in Path("renders").glob("*-s*-*") if (p / "meta.json").is_file()
    )
    det = DetectorConfig()
    print("entry size overlap_rig overlap_img rot_err_deg dir_err_deg s_per_view rho_p rho_e")
    for entry in entries:
        views = load_views(entry)
        if views[0].camera.width != 640:
            continue
        pools = [detect(v, det) for v in views]
        blind = [v.without_pose() for v in views]
        rig = rig_geometry(views, pools, SignalConfig())
        posed, _ = compute_signals(views, pools, det, SignalConfig())
        n_rig = sum(len(o) for o in rig.overlap) // 2
        for size in map(int, args.sizes.split(",")):
            cfg = SignalConfig(first_pass=size)
            t = time.perf_counter()
            geo = image_geometry(blind, pools, cfg)
            secs = (time.perf_counter() - t) / len(views)
            rot, dirs = [], []
            for (i, j), (_, b) in geo.pair_frame.items():
                ci, cj = views[i].camera, views[j].camera
                R = cj.R @ ci.R.T
                tt = cj.t - R @ ci.t
                rot.append(angle_deg(b.R @ R.T))
                cosd = b.t @ tt / np.linalg.norm(tt)
                dirs.append(float(np.degrees(np.arccos(np.clip(cosd, -1, 1)))))
            est, _ = compute_signals(blind, pools, det, cfg)
            rho = [
                spearmanr(
                    np.concatenate([getattr(s, k) for s in posed]),
                    np.concatenate([getattr(s, k) for s in est]),
                ).statistic
                for k in ("parallax", "epipolar")
            ]
            print(
                f"{entry.name} {size} {n_rig} {len(geo.pair_frame)} "
                f"{np.median(rot) if rot else np.nan:.3f} {np.median(dirs) if dirs else np.nan:.2f} "
                f"{secs:.3f} {rho[0]:.2f} {rho[1]:.2f}"
            )


if __name__ == "__main__":
    main()
