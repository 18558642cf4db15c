"""The front end on a dataset of photographs, alone: seconds per image (detection and every
signal, under the geometry estimated from the images, as the `sfm` task has it) and the
process's peak memory, at a chosen working size. One process, nothing cached.

    .venv/bin/python benchmarks/frontend_photos.py DATASET [--max-image-size 3200] [--grant images]

A 12 MP copy of a dataset for this measurement: resize its images and rescale its cameras
(`pycolmap.Camera.rescale`) into a folder outside the repository.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import IMAGES, RIG, SignalConfig
from bench.frontend.stage import front_end


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--max-image-size", type=int, default=DetectorConfig.max_image_size)
    ap.add_argument("--grant", choices=(RIG, IMAGES), default=IMAGES)
    args = ap.parse_args()
    det = DetectorConfig(max_image_size=args.max_image_size)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as cache:
        fe = front_end(args.dataset, det, SignalConfig(), Path(cache), args.grant)
    seconds = time.perf_counter() - t
    n, cam = len(fe.views), fe.views[0].camera
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB -> GB
    print(
        f"{args.dataset.name}: {n} views of {cam.width}x{cam.height}, working size at most "
        f"{args.max_image_size} px: {seconds:.1f} s, {seconds / n:.2f} s per image "
        f"(detection {fe.seconds['detect'] / n:.2f}); candidates per view "
        f"{[len(p) for p in fe.pools]}; peak memory {peak:.2f} GB"
    )
    print("seconds over all views:", {k: round(v, 1) for k, v in fe.seconds.items()})


if __name__ == "__main__":
    main()
