"""The candidate pool: one set of keypoints and descriptors per view, shared by all
policies, detected by the pool's detector (`bench.frontend.pools`).

Keypoints are stored in COLMAP's pixel convention (pixel (0, 0)'s centre at (0.5, 0.5)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from bench import BenchError
from bench.frontend.pools import POOLS, aliked, get_pool
from bench.frontend.views import View


@dataclass(frozen=True)
class DetectorConfig:
    """The detector that builds every view's candidate pool."""

    detector: str = "sift"
    """The pool's detector and descriptor (`bench.frontend.pools`): sift, orb, akaze, or
    the learned aliked, disk or xfeat (the `learned` extra), or one of a pool module's."""
    sift_contrast: float = 0.005
    """SIFT contrast threshold (OpenCV's default is 0.04; low, so that the pool is several
    times the budget even on the weakly textured corridor)."""
    orb_features: int = 5000
    """ORB: number of keypoints to keep."""
    akaze_threshold: float = 0.0002
    """AKAZE detector response threshold."""
    max_image_size: int = 3200
    """Longest image side the front end works at, px (COLMAP's max_image_size): a larger
    photograph is detected, and its signals computed, on a copy downscaled to it, and its
    keypoints are kept in full-resolution pixels."""
    max_features: int = 8192
    """Most candidates per view: the strongest by detector response (COLMAP's
    max_num_features); bounds the front end's memory on large photographs."""
    learned_variant: str = "aliked-n16"
    """ALIKED's network: aliked-n16, aliked-n16rot, aliked-n32 or aliked-t16 (LightGlue's
    ALIKED weights were trained on aliked-n16's descriptors)."""
    learned_max_edge: int = 1024
    """The learned pools (ALIKED, DISK, XFeat): longest side, px, of the downscaled copy
    the network detects on (LightGlue's training size); keypoints are returned in
    full-resolution pixels."""
    learned_keypoints: int = 4096
    """The learned pools: most keypoints per view, the highest-scoring (the pool; above the
    largest budget; max_features bounds the OpenCV detectors')."""
    aliked_threshold: float = 0.01
    """ALIKED's detection score threshold (LightGlue's default is 0.2; low, so that the
    pool is above the budget on small, weakly textured views: 330-610 candidates per
    view of the table at 320x240, SIFT's 330-390)."""

    def validate(self) -> DetectorConfig:
        if self.detector not in POOLS:
            raise BenchError(f"unknown detector {self.detector!r}; valid: {', '.join(POOLS)}")
        if self.max_image_size < 64 or self.max_features < 1:
            raise BenchError("detector.max_image_size must be >= 64 and max_features >= 1")
        if self.learned_variant not in aliked.VARIANTS:
            raise BenchError(
                f"unknown detector.learned_variant {self.learned_variant!r}; valid: "
                + ", ".join(aliked.VARIANTS)
            )
        if self.learned_max_edge < 64 or self.learned_keypoints < 1 or self.aliked_threshold <= 0:
            raise BenchError(
                "detector.learned_max_edge must be >= 64, learned_keypoints >= 1 and "
                "aliked_threshold > 0"
            )
        POOLS[self.detector].require()
        return self


@dataclass
class Candidates:
    """The candidate keypoints of one view."""

    xy: np.ndarray
    """(N, 2) float64 x, y in pixels, COLMAP convention (the image's corner is 0, 0; the
    first pixel's centre 0.5, 0.5)."""
    size: np.ndarray
    """(N,) float64 keypoint diameter in pixels (the detector's scale; a learned
    detector's is nominal, `bench.frontend.learned`)."""
    angle: np.ndarray
    """(N,) float64 orientation in degrees [0, 360) (OpenCV's; -1: none)."""
    response: np.ndarray
    """(N,) float64 detector response (strength; its scale depends on the detector; a
    learned detector's detection score)."""
    descriptors: np.ndarray
    """(N, D): float32 unit-length for SIFT, uint8 bit strings for ORB/AKAZE."""

    def __len__(self) -> int:
        return len(self.xy)

    def scaled(self, sx: float, sy: float) -> Candidates:
        """The same candidates in an image scaled by (sx, sy) (COLMAP's pixel convention
        scales with the image: its origin is the image's corner)."""
        return replace(self, xy=self.xy * [sx, sy], size=self.size * math.sqrt(sx * sy))


def tile_of(xy: np.ndarray, width: int, height: int, tiles: tuple[int, int]) -> np.ndarray:
    """Index of the tile (row-major, tiles = columns x rows) holding each point."""
    cx = np.clip((xy[:, 0] / width * tiles[0]).astype(int), 0, tiles[0] - 1)
    cy = np.clip((xy[:, 1] / height * tiles[1]).astype(int), 0, tiles[1] - 1)
    return cy * tiles[0] + cx


def detect(view: View, cfg: DetectorConfig) -> Candidates:
    """Detect and describe one view's candidates with its pool's detector
    (`bench.frontend.pools`)."""
    return Candidates(*get_pool(cfg.detector).detect(view.image, cfg))


def detect_points(gray: np.ndarray, cfg: DetectorConfig) -> np.ndarray:
    """Keypoint locations only (COLMAP convention), for re-detection under perturbations."""
    return get_pool(cfg.detector).points(gray, cfg)


def descriptor_distances(a: np.ndarray, b: np.ndarray, squared: bool = False) -> np.ndarray:
    """Pairwise descriptor distances (float32): L2 for float descriptors, Hamming fraction
    for binary ones; `squared` returns their squares (cheaper, same order)."""
    if a.dtype == np.uint8:
        A, B = (np.unpackbits(x, axis=1).astype(np.float32) for x in (a, b))
        D = (A @ (1 - B).T + (1 - A) @ B.T) / A.shape[1]
        return D * D if squared else D
    a, b = a.astype(np.float32, copy=False), b.astype(np.float32, copy=False)
    na, nb = (a * a).sum(1), (b * b).sum(1)
    d2 = a @ b.T
    d2 *= -2
    if np.allclose(na, 1, atol=1e-4) and np.allclose(nb, 1, atol=1e-4):
        d2 += 2  # unit descriptors (SIFT candidates): |a - b|^2 = 2 - 2 a.b
    else:
        d2 += na[:, None]
        d2 += nb[None]
    np.maximum(d2, 0, out=d2)
    return d2 if squared else np.sqrt(d2, out=d2)


def tentative_matches(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float) -> np.ndarray:
    """(M, 2) index pairs: mutual nearest neighbours that pass the ratio test."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros((0, 2), np.int64)
    D = descriptor_distances(desc_a, desc_b)
    column_min = D.min(0)
    winners = D == column_min
    tied = np.flatnonzero(winners.sum(0) > 1)
    first_of_tie = np.full(D.shape[1], -1)
    first_of_tie[tied] = winners[:, tied].argmax(0)
    nn_ab, first, second = nearest_two(D)
    a = np.arange(len(desc_a))
    # mutual: row a is its nearest column's argmin, i.e. holds the column's minimum, the
    # first row to hold it where several do (D.argmin(0) reads D strided, at 5-10 times
    # the cost: docs/speed.md)
    tie = first_of_tie[nn_ab]
    mutual = np.where(tie < 0, first == column_min[nn_ab], tie == a)
    keep = mutual & (first < ratio * second)
    return np.stack([a[keep], nn_ab[keep]], 1)


def nearest_two(D: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of D: the column of its smallest value (the first, as argmin), that value, and
    the second smallest (the values `np.partition(D, 1, axis=1)[:, :2]` finds, in a
    fraction of its time). Overwrites each row's smallest entry with infinity."""
    rows = np.arange(len(D))
    col = D.argmin(1)
    first = D[rows, col]
    D[rows, col] = np.inf
    return col, first, D.min(1)
