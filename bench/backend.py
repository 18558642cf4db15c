"""The reconstruction back end on COLMAP (pycolmap). Sees only selected keypoints, their
descriptors and the calibration.

1. Tentative matches between the selected features of every pair of views: mutual nearest
   neighbours in descriptor space that also pass Lowe's ratio test (d1 < ratio * d2).
2. Geometric verification per pair with COLMAP's calibrated two-view geometry (RANSAC on
   the essential matrix, homography checks) using the known intrinsics; inliers are kept.
3. Tracks and triangulation with the known poses: a COLMAP database holding exactly the
   selected keypoints and the verified matches, and `pycolmap.triangulate_points` on a
   reconstruction whose poses are the rig's (poses and intrinsics are held fixed; points
   are refined by COLMAP's bundle adjustment).

Triangulation options (the same for every policy): two-view tracks are kept (COLMAP drops
them by default; with six views and a few hundred features per view most tracks are
short); COLMAP's minimum triangulation angle of 1.5 degrees and its 4 px reprojection
limits are kept, so near-degenerate ray intersections are not created. RANSAC and the
triangulator are seeded and single-threaded, so a run is reproducible.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np
import pycolmap

from bench.camera import Camera
from bench.signals import descriptor_distances

pycolmap.logging.minloglevel = 2  # errors only: COLMAP's per-image progress would drown ours


@dataclass(frozen=True)
class BackendConfig:
    """Matching, verification and triangulation settings."""

    ratio: float = 0.8
    """Lowe ratio test threshold for tentative matches (with mutual nearest neighbours)."""
    ransac_max_error: float = 4.0
    """RANSAC inlier threshold of the two-view verification, in pixels (COLMAP's default)."""
    min_tri_angle: float = 1.5
    """Minimum triangulation angle in degrees for a track to become a point (COLMAP's default)."""
    keep_two_view_tracks: bool = True
    """Triangulate tracks seen in only two views (COLMAP's point triangulator drops them by default)."""
    seed: int = 0
    """Seed of COLMAP's RANSAC and triangulator."""


@dataclass
class PairMatches:
    """Matches between the selected features of views i < j (indices into the selections)."""

    i: int
    j: int
    tentative: np.ndarray
    verified: np.ndarray
    config: str
    """COLMAP's two-view configuration (e.g. CALIBRATED, PLANAR, DEGENERATE)."""


@dataclass
class Reconstruction:
    """The back end's result: a COLMAP model with the rig's poses, or the reason there is none."""

    pairs: list[PairMatches]
    model: pycolmap.Reconstruction | None
    failure: str | None
    seconds: dict[str, float] = field(default_factory=dict)


def tentative_matches(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float) -> np.ndarray:
    """(M, 2) index pairs: mutual nearest neighbours that pass the ratio test."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros((0, 2), np.int64)
    D = descriptor_distances(desc_a, desc_b)
    two = np.partition(D, 1, axis=1)[:, :2]
    nn_ab, nn_ba = D.argmin(1), D.argmin(0)
    a = np.arange(len(desc_a))
    keep = (nn_ba[nn_ab] == a) & (two[:, 0] < ratio * two[:, 1])
    return np.stack([a[keep], nn_ab[keep]], 1)


def colmap_camera(cam: Camera) -> pycolmap.Camera:
    c = pycolmap.Camera(
        model="PINHOLE",
        width=cam.width,
        height=cam.height,
        params=[cam.fx, cam.fy, cam.cx, cam.cy],
        camera_id=1,
    )
    c.has_prior_focal_length = True  # otherwise COLMAP does not estimate a calibrated geometry
    return c


def verify(
    cam_a: Camera,
    xy_a: np.ndarray,
    cam_b: Camera,
    xy_b: np.ndarray,
    matches: np.ndarray,
    cfg: BackendConfig,
) -> tuple[np.ndarray, str]:
    """COLMAP's calibrated two-view geometry on the tentative matches: (inliers, configuration)."""
    if len(matches) < 5:
        return np.zeros((0, 2), np.int64), "TOO_FEW_MATCHES"
    opts = pycolmap.TwoViewGeometryOptions()
    opts.ransac.max_error = cfg.ransac_max_error
    opts.ransac.random_seed = cfg.seed
    tvg = pycolmap.estimate_calibrated_two_view_geometry(
        colmap_camera(cam_a),
        xy_a.astype(np.float64),
        colmap_camera(cam_b),
        xy_b.astype(np.float64),
        matches.astype(np.uint32),
        opts,
    )
    config = pycolmap.TwoViewGeometryConfiguration(int(tvg.config)).name
    return np.asarray(tvg.inlier_matches, np.int64).reshape(-1, 2), config


def match_and_verify(
    cams: list[Camera], xy: list[np.ndarray], desc: list[np.ndarray], cfg: BackendConfig
) -> tuple[list[PairMatches], dict[str, float]]:
    pairs, seconds = [], {"match": 0.0, "verify": 0.0}
    for i, j in combinations(range(len(cams)), 2):
        t = time.perf_counter()
        m = tentative_matches(desc[i], desc[j], cfg.ratio)
        seconds["match"] += time.perf_counter() - t
        t = time.perf_counter()
        inliers, config = verify(cams[i], xy[i], cams[j], xy[j], m, cfg)
        seconds["verify"] += time.perf_counter() - t
        pairs.append(PairMatches(i, j, m, inliers, config))
    return pairs, seconds


def _write_database(
    path: Path, cams: list[Camera], names: list[str], xy: list[np.ndarray], pairs: list[PairMatches]
) -> None:
    db = pycolmap.Database.open(str(path))
    try:
        db.write_camera(colmap_camera(cams[0]), use_camera_id=True)
        for k, name in enumerate(names):
            db.write_image(
                pycolmap.Image(name=name, camera_id=1, image_id=k + 1), use_image_id=True
            )
            db.write_keypoints(k + 1, xy[k].astype(np.float32).reshape(-1, 2))
        for p in pairs:
            db.write_matches(p.i + 1, p.j + 1, p.tentative.astype(np.uint32))
            tvg = pycolmap.TwoViewGeometry()
            tvg.inlier_matches = p.verified.astype(np.uint32)
            tvg.config = pycolmap.TwoViewGeometryConfiguration.CALIBRATED
            db.write_two_view_geometry(p.i + 1, p.j + 1, tvg)
    finally:
        db.close()


def known_pose_model(
    cams: list[Camera], names: list[str], xy: list[np.ndarray]
) -> pycolmap.Reconstruction:
    """A COLMAP model with the rig's intrinsics and poses, each image holding its selected
    keypoints (all of them, so the export is a complete record of the selection)."""
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(colmap_camera(cams[0]))
    for k, (cam, name) in enumerate(zip(cams, names)):
        image = pycolmap.Image(
            name=name,
            keypoints=xy[k].astype(np.float64).reshape(-1, 2),
            camera_id=1,
            image_id=k + 1,
        )
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(cam.R), cam.t))
    return rec


def triangulate(
    image_dir: Path,
    cams: list[Camera],
    names: list[str],
    xy: list[np.ndarray],
    pairs: list[PairMatches],
    cfg: BackendConfig,
) -> pycolmap.Reconstruction:
    """Triangulate the verified tracks with the rig's known poses through COLMAP."""
    work = Path(tempfile.mkdtemp(prefix="bench-colmap-"))
    try:
        _write_database(work / "database.db", cams, names, xy, pairs)
        rec = known_pose_model(cams, names, xy)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.triangulation.ignore_two_view_tracks = not cfg.keep_two_view_tracks
        opts.triangulation.min_angle = cfg.min_tri_angle
        opts.mapper.filter_min_tri_angle = cfg.min_tri_angle
        opts.triangulation.random_seed = cfg.seed
        opts.random_seed = cfg.seed
        opts.num_threads = 1
        (work / "out").mkdir()
        return pycolmap.triangulate_points(
            rec, work / "database.db", image_dir, work / "out", options=opts
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)


def reconstruct(
    image_dir: Path,
    cams: list[Camera],
    xy: list[np.ndarray],
    desc: list[np.ndarray],
    cfg: BackendConfig,
) -> Reconstruction:
    """Match, verify and triangulate; failures are recorded as a reason, never raised."""
    names = [f"view_{k:02d}.png" for k in range(len(cams))]
    pairs, seconds = match_and_verify(cams, xy, desc, cfg)
    if sum(len(p.verified) for p in pairs) == 0:
        return Reconstruction(pairs, None, "no pair of views has verified matches", seconds)
    t = time.perf_counter()
    try:
        model = triangulate(image_dir, cams, names, xy, pairs, cfg)
    except Exception as e:  # COLMAP failures become a recorded reason
        return Reconstruction(
            pairs,
            None,
            f"triangulation failed: {type(e).__name__}: {e}",
            seconds | {"triangulate": time.perf_counter() - t},
        )
    seconds["triangulate"] = time.perf_counter() - t
    failure = None if model.num_points3D() > 0 else "no track could be triangulated"
    return Reconstruction(pairs, model, failure, seconds)


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
