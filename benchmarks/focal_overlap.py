"""The overlap graph that the geometry from the images finds (`bench select` without
--cameras) with three focal lengths: the dataset's true one, COLMAP's guess (1.2 x
max(width, height), what `bench select` used before it estimated the focal length) and
the estimate from the images (`bench.frontend.geometry.estimate_focal`).

    .venv/bin/python benchmarks/focal_overlap.py /work/shared/datasets/strecha-herzjesu-p8
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from bench.frontend.features import DetectorConfig, detect
from bench.frontend.geometry import SignalConfig, estimate_focal, image_geometry
from bench.frontend.stage import with_focal
from bench.frontend.views import DEFAULT_FOCAL_FACTOR, load_views


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", help="a dataset in the COLMAP layout (images/, sparse/)")
    a = ap.parse_args()
    det, sig = DetectorConfig(), SignalConfig()
    true = [v.without_pose().scale_to(det.max_image_size)[0] for v in load_views(a.dataset)]
    t = time.perf_counter()
    pools = [detect(v, det) for v in true]
    print(f"detected {len(true)} views in {time.perf_counter() - t:.1f} s")
    guessed = [  # as `bench select` reads a photograph without EXIF
        replace(v, camera=replace(v.camera, cx=v.camera.width / 2, cy=v.camera.height / 2))
        for v in true
    ]
    guessed = [replace(with_focal(v, DEFAULT_FOCAL_FACTOR), focal_known=False) for v in guessed]
    t = time.perf_counter()
    found = estimate_focal(guessed, pools, sig)
    print(f"estimate_focal: {found} in {time.perf_counter() - t:.1f} s")
    runs = {"true": true, "guess": guessed}
    if found.factor:
        runs["estimated"] = [with_focal(v, found.factor) for v in guessed]
    n = len(true)
    for name, views in runs.items():
        c = views[0].camera
        geo = image_geometry(views, pools, sig)
        pairs = sorted((i, j) for i in range(n) for j in geo.overlap[i] if i < j)
        adjacent = sum(j == i + 1 for i, j in pairs)
        print(
            f"{name:9s} f={c.fx:7.1f} px: {len(pairs)} overlapping pairs, {adjacent} of "
            f"{n - 1} adjacent: {' '.join(f'{i}-{j}' for i, j in pairs)}"
        )


if __name__ == "__main__":
    main()
