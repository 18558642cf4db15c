"""COLMAP's calibrated two-view geometry, in one place: what the front end estimates the
geometry of photographs with (`bench.frontend.geometry`) and what the back end verifies a
selection's matches with (`bench.backend.matching`), and the camera both hand to COLMAP."""

from __future__ import annotations

import numpy as np
import pycolmap

from bench.camera import Camera


def colmap_camera(cam: Camera, camera_id: int = 1) -> pycolmap.Camera:
    """A pinhole camera as COLMAP holds it, its focal length a trusted prior."""
    c = pycolmap.Camera(
        model="PINHOLE",
        width=cam.width,
        height=cam.height,
        params=[cam.fx, cam.fy, cam.cx, cam.cy],
        camera_id=camera_id,
    )
    c.has_prior_focal_length = True  # otherwise COLMAP does not estimate a calibrated geometry
    return c


def verification_options(
    max_error: float, seed: int, max_trials: int | None = None
) -> pycolmap.TwoViewGeometryOptions:
    """COLMAP's two-view verification: its RANSAC threshold (px), seed and trial limit,
    with the relative pose computed."""
    opts = pycolmap.TwoViewGeometryOptions()
    opts.ransac.max_error = max_error
    opts.ransac.random_seed = seed
    if max_trials is not None:
        opts.ransac.max_num_trials = max_trials
    opts.compute_relative_pose = True
    return opts


def two_view_geometry(
    cam_a: Camera,
    xy_a: np.ndarray,
    cam_b: Camera,
    xy_b: np.ndarray,
    matches: np.ndarray,
    opts: pycolmap.TwoViewGeometryOptions,
) -> pycolmap.TwoViewGeometry:
    """COLMAP's calibrated two-view geometry of tentative matches (intrinsics only), with
    the relative pose `cam2_from_cam1` (b from a) where it can be estimated."""
    return pycolmap.estimate_calibrated_two_view_geometry(
        colmap_camera(cam_a),
        xy_a.astype(np.float64),
        colmap_camera(cam_b),
        xy_b.astype(np.float64),
        matches.astype(np.uint32),
        opts,
    )


def configuration(tvg: pycolmap.TwoViewGeometry) -> str:
    """COLMAP's name of a two-view configuration (e.g. CALIBRATED, PLANAR, DEGENERATE)."""
    return pycolmap.TwoViewGeometryConfiguration(int(tvg.config)).name
