"""OpenCV's detectors as pools: SIFT (the benchmark's default, COLMAP's detector), ORB
and AKAZE, each matched by the ratio test. Detected on the view's gray image at full
resolution (the front end downscales a view larger than `max_image_size` first); the
pool is the `max_features` strongest by response, in the detector's order."""

from __future__ import annotations

import cv2
import numpy as np

from bench.frontend.pools.registry import Pool, register_pool, strongest_first


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def _create(name: str, cfg):
    if name == "sift":
        return cv2.SIFT_create(contrastThreshold=cfg.sift_contrast)
    if name == "orb":
        return cv2.ORB_create(nfeatures=cfg.orb_features)
    akaze = getattr(cv2, "AKAZE_create", None) or cv2.xfeatures2d.AKAZE_create  # OpenCV 5
    return akaze(threshold=cfg.akaze_threshold)


def keypoint_arrays(kps) -> tuple[np.ndarray, ...]:
    """xy (COLMAP's convention: OpenCV's pixel centre is at 0, so 0.5 is added once,
    here), size, angle and response of OpenCV keypoints."""
    xy = np.array([k.pt for k in kps], float).reshape(-1, 2) + 0.5
    return (
        xy,
        np.array([k.size for k in kps], float),
        np.array([k.angle for k in kps], float),
        np.array([k.response for k in kps], float),
    )


def _pool(name: str, binary: bool, tau: float) -> Pool:
    def detect(image: np.ndarray, cfg) -> tuple[np.ndarray, ...]:
        kps, desc = _create(name, cfg).detectAndCompute(_gray(image), None)
        if len(kps) > cfg.max_features:
            keep = np.sort(strongest_first([k.response for k in kps])[: cfg.max_features])
            kps, desc = [kps[k] for k in keep], desc[keep]
        if desc is None:
            desc = np.zeros((0, 32 if binary else 128), np.uint8 if binary else np.float32)
        if not binary:
            desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
        return (*keypoint_arrays(kps), desc.astype(np.uint8 if binary else np.float32))

    def points(gray: np.ndarray, cfg) -> np.ndarray:
        return keypoint_arrays(_create(name, cfg).detect(gray, None))[0]

    return register_pool(Pool(name, detect, points, tau, binary=binary))


SIFT = _pool("sift", binary=False, tau=0.3)
ORB = _pool("orb", binary=True, tau=0.2)
AKAZE = _pool("akaze", binary=True, tau=0.2)
