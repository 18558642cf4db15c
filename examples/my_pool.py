"""A candidate pool of your own detector, complete: upright SIFT (OpenCV's SIFT keypoints,
each described at angle 0, as COLMAP's `--SiftExtraction.upright 1` describes them for
cameras that do not roll), matched by the ratio test.

    bench run --quick --pool-module examples/my_pool.py --pools sift,sift-upright
    bench verdict examples/my_pool.py        # against results/published-pools
"""

import cv2
import numpy as np

from bench.frontend.pools import Pool, register_pool, strongest_first
from bench.frontend.pools.opencv import keypoint_arrays


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def detect(image: np.ndarray, cfg):
    """The `max_features` strongest SIFT locations (one per location: SIFT repeats a
    keypoint for each of its orientations), each described upright."""
    gray = _gray(image)
    sift = cv2.SIFT_create(contrastThreshold=cfg.sift_contrast)
    kps = sift.detect(gray, None)
    order = strongest_first([k.response for k in kps])
    seen, kept = set(), []
    for k in order:
        where = (round(kps[k].pt[0], 3), round(kps[k].pt[1], 3), round(kps[k].size, 3))
        if where not in seen and len(kept) < cfg.max_features:
            seen.add(where)
            kept.append(kps[k])
    for k in kept:
        k.angle = 0.0
    kept, desc = sift.compute(gray, kept)
    desc = np.zeros((0, 128), np.float32) if desc is None else desc
    desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    return (*keypoint_arrays(kept), desc.astype(np.float32))


def points(gray: np.ndarray, cfg) -> np.ndarray:
    """The locations alone (the re-detection signal)."""
    return keypoint_arrays(cv2.SIFT_create(contrastThreshold=cfg.sift_contrast).detect(gray))[0]


register_pool(Pool("sift-upright", detect, points, duplicate_distance=0.3, label="upright SIFT"))
