"""`bench select` against COLMAP's own SIFT extraction on the same photographs: seconds
per image at the photographs' size and upsampled to about 12 megapixels (JPEG, quality
95, in a temporary folder), without poses or EXIF (the focal length is estimated), and
where `bench select`'s time goes. COLMAP extracts with its defaults (8192 features, CPU),
its images downscaled to 3200 px as `bench select`'s are (`detector.max_image_size`).

    .venv/bin/python benchmarks/select_speed.py DIR [--policy adaptive-fast] [--budget 1024]
        [--megapixels 12] [--limit 8]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import cv2
import pycolmap

from bench.frontend.features import DetectorConfig
from bench.frontend.views import image_files
from bench.harness.select import SelectRequest, select_to_database


def colmap_seconds(folder: Path, db: Path, threads: int) -> float:
    """Seconds of `pycolmap.extract_features` on every image of `folder`."""
    opts = pycolmap.FeatureExtractionOptions()
    opts.num_threads = threads
    opts.max_image_size = DetectorConfig().max_image_size
    t = time.perf_counter()
    pycolmap.extract_features(db, folder, extraction_options=opts, device=pycolmap.Device.cpu)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("images", type=Path, help="a folder of photographs")
    ap.add_argument("--policy", default="adaptive-fast")
    ap.add_argument("--budget", type=int, default=1024)
    ap.add_argument("--megapixels", type=float, default=12.0)
    ap.add_argument("--limit", type=int, default=8, help="the first N images")
    a = ap.parse_args()
    names = image_files(a.images)[: a.limit]
    pycolmap.logging.minloglevel = 2
    with tempfile.TemporaryDirectory() as tmp:
        for scale in (None, a.megapixels):
            folder = Path(tmp) / f"images-{scale}"
            folder.mkdir()
            for n in names:
                img = cv2.imread(str(a.images / n))
                if scale is not None:
                    s = math.sqrt(scale * 1e6 / (img.shape[0] * img.shape[1]))
                    img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
                cv2.imwrite(
                    str(folder / f"{Path(n).stem}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 95]
                )
            h, w = img.shape[:2]
            seconds: dict[str, float] = {}
            t = time.perf_counter()
            select_to_database(
                SelectRequest(folder, a.policy, a.budget), Path(tmp) / f"out-{scale}", seconds
            )
            ours = (time.perf_counter() - t) / len(names)
            colmap = {
                k: colmap_seconds(folder, Path(tmp) / f"colmap-{scale}-{k}.db", k) / len(names)
                for k in (1, -1)
            }
            steps = ", ".join(f"{k} {v / len(names):.2f}" for k, v in seconds.items())
            print(
                f"{w}x{h} ({w * h / 1e6:.1f} MP), {len(names)} images, {a.policy} B={a.budget}: "
                f"bench select {ours:.2f} s/image ({steps}); COLMAP SIFT {colmap[1]:.2f} s/image "
                f"on 1 thread, {colmap[-1]:.2f} on all; ratio {ours / colmap[1]:.2f} and "
                f"{ours / colmap[-1]:.2f}"
            )


if __name__ == "__main__":
    main()
