"""Matching and geometric verification of the selected features of every pair of views.

1. Tentative matches (`BackendConfig.matcher`): `ratio`, mutual nearest neighbours in
   descriptor space that also pass Lowe's ratio test (d1 < ratio * d2), on the GPU where
   one is present, with exactly the CPU's matches (`bench.backend.gpu`); or the pool's
   learned matcher (`bench.frontend.pools`: LightGlue for ALIKED and DISK, LighterGlue for
   XFeat).
2. Verification per pair with COLMAP's calibrated two-view geometry (RANSAC on the
   essential matrix, homography checks) using the known intrinsics; inliers are kept,
   with the relative pose COLMAP estimates from them (the `pairs` task's prediction).
RANSAC is seeded, so a run is reproducible.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from bench import BenchError
from bench.backend import gpu
from bench.camera import Camera
from bench.frontend import features
from bench.frontend.features import Candidates
from bench.frontend.pools import POOLS, RATIO
from bench.twoview import configuration, two_view_geometry, verification_options


@dataclass(frozen=True)
class BackendConfig:
    """Matching, verification and reconstruction settings."""

    ratio: float = 0.8
    """Lowe ratio test threshold for tentative matches (with mutual nearest neighbours)."""
    matcher: str = "ratio"
    """Tentative matches: ratio (mutual nearest neighbours passing the ratio test) or the
    pool's learned matcher (lightglue for aliked and disk, lighterglue for xfeat)."""
    ransac_max_error: float = 4.0
    """RANSAC inlier threshold of the two-view verification, in pixels (COLMAP's default)."""
    min_tri_angle: float = 1.5
    """Minimum triangulation angle in degrees for a track to become a point (COLMAP's default)."""
    seed: int = 0
    """Seed of COLMAP's RANSAC, triangulator and mapper."""

    def validate(self) -> BackendConfig:
        if not 0 < self.ratio <= 1:
            raise BenchError(f"backend.ratio must lie in (0, 1], got {self.ratio}")
        if self.ransac_max_error <= 0 or self.min_tri_angle < 0:
            raise BenchError("backend.ransac_max_error must be > 0 and min_tri_angle >= 0")
        return self


@dataclass
class PairMatches:
    """Matches between the selected features of views i < j (indices into the selections)."""

    i: int
    j: int
    tentative: np.ndarray
    verified: np.ndarray
    config: str
    """COLMAP's two-view configuration (e.g. CALIBRATED, PLANAR, DEGENERATE)."""
    pose: np.ndarray | None = None
    """View j's camera from view i's, [R | t] (3, 4) with a unit translation t, as COLMAP's
    verification estimated it (None where it kept no inliers or estimated no pose)."""

    @property
    def rotation(self) -> np.ndarray | None:
        """The rotation of `pose` (None without one)."""
        return None if self.pose is None else self.pose[:, :3]


def verify(
    cam_a: Camera,
    xy_a: np.ndarray,
    cam_b: Camera,
    xy_b: np.ndarray,
    matches: np.ndarray,
    cfg: BackendConfig,
) -> tuple[np.ndarray, str, np.ndarray | None]:
    """COLMAP's calibrated two-view geometry on the tentative matches: (inliers,
    configuration, [R | t] of b from a where COLMAP estimated the relative pose from them)."""
    if len(matches) < 5:
        return np.zeros((0, 2), np.int64), "TOO_FEW_MATCHES", None
    opts = verification_options(cfg.ransac_max_error, cfg.seed)
    tvg = two_view_geometry(cam_a, xy_a, cam_b, xy_b, matches, opts)
    inliers = np.asarray(tvg.inlier_matches, np.int64).reshape(-1, 2)
    rel = tvg.cam2_from_cam1
    if not len(inliers) or rel is None:
        return inliers, configuration(tvg), None
    pose = np.c_[np.asarray(rel.rotation.matrix()), np.asarray(rel.translation)]
    return inliers, configuration(tvg), pose


def tentative_matches(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float) -> np.ndarray:
    """(M, 2) index pairs: mutual nearest neighbours that pass the ratio test
    (`bench.frontend.features.tentative_matches`), on the GPU where one is present: the
    same matches (`bench.backend.gpu`)."""
    out = gpu.ratio_matches(desc_a, desc_b, ratio)
    return features.tentative_matches(desc_a, desc_b, ratio) if out is None else out


def check_matcher(cfg: BackendConfig, detector: str) -> None:
    """Refuse, in one line, a matcher the pool cannot be matched with."""
    pool = POOLS[detector]
    if cfg.matcher not in pool.matchers:
        raise BenchError(
            f"backend.matcher={cfg.matcher}: the {detector} pool is matched with "
            f"{' or '.join(pool.matchers)}"
        )


def tentative(
    cams: list[Camera],
    xy: list[np.ndarray],
    desc: list[np.ndarray],
    cfg: BackendConfig,
    detector: str,
) -> Callable[[int, int], np.ndarray]:
    """The tentative matches (M, 2) of views i and j under `cfg.matcher`, as a function."""
    check_matcher(cfg, detector)
    if cfg.matcher == RATIO:
        return lambda i, j: tentative_matches(desc[i], desc[j], cfg.ratio)
    sides = [(x, d, (c.width, c.height)) for c, x, d in zip(cams, xy, desc)]
    return lambda i, j: POOLS[detector].match(sides[i], sides[j])


def match_and_verify(
    cams: list[Camera],
    xy: list[np.ndarray],
    desc: list[np.ndarray],
    cfg: BackendConfig,
    detector: str,
) -> tuple[list[PairMatches], dict[str, float]]:
    """Every pair of views (i < j): the tentative matches of the pool's `detector` under
    `cfg.matcher`, and their verification; with the seconds of each."""
    pairs, seconds = [], {"match": 0.0, "verify": 0.0}
    match = tentative(cams, xy, desc, cfg, detector)
    for i, j in combinations(range(len(cams)), 2):
        t = time.perf_counter()
        m = match(i, j)
        seconds["match"] += time.perf_counter() - t
        t = time.perf_counter()
        inliers, config, pose = verify(cams[i], xy[i], cams[j], xy[j], m, cfg)
        seconds["verify"] += time.perf_counter() - t
        pairs.append(PairMatches(i, j, m, inliers, config, pose))
    return pairs, seconds


def matcher(cams: list[Camera], pools: list[Candidates], cfg: BackendConfig, detector: str):
    """Selections per view -> the verified pairs of those keypoints (for the feedback loop)."""

    def match(selection: list[np.ndarray]) -> list[PairMatches]:
        xy = [c.xy[s] for c, s in zip(pools, selection)]
        desc = [c.descriptors[s] for c, s in zip(pools, selection)]
        return match_and_verify(cams, xy, desc, cfg, detector)[0]

    return match


def expected_ransac_iterations(
    inlier_ratio: float, sample_size: int = 5, confidence: float = 0.999
) -> float:
    """RANSAC trials needed to draw one all-inlier minimal sample with the given confidence,
    within COLMAP's trial bounds (100 to 10000)."""
    w = min(max(inlier_ratio, 0.0), 1.0) ** sample_size
    trials = (
        math.log(1 - confidence) / math.log1p(-w) if 0 < w < 1 else (1.0 if w >= 1 else math.inf)
    )
    return float(min(max(trials, 100.0), 10000.0))
