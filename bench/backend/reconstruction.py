"""Reconstruction on COLMAP (pycolmap) from the selected keypoints and verified matches.

Tracks and triangulation with the known poses: a COLMAP database holding exactly the
selected keypoints and the verified matches, and `pycolmap.triangulate_points` on a
reconstruction whose poses are the rig's (poses and intrinsics are held fixed; points
are refined by COLMAP's bundle adjustment).

Triangulation options (the same for every policy): two-view tracks are kept (COLMAP drops
them by default; with six views and a few hundred features per view most tracks are
short); COLMAP's minimum triangulation angle of 1.5 degrees and its 4 px reprojection
limits are kept, so near-degenerate ray intersections are not created. The triangulator
is seeded and single-threaded, so a run is reproducible.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from bench.backend.matching import BackendConfig, PairMatches, colmap_camera, match_and_verify
from bench.camera import Camera

pycolmap.logging.minloglevel = 2  # errors only: COLMAP's per-image progress would drown ours


@dataclass
class Reconstruction:
    """The back end's result: a COLMAP model with the rig's poses, or the reason there is none."""

    pairs: list[PairMatches]
    model: pycolmap.Reconstruction | None
    failure: str | None
    seconds: dict[str, float] = field(default_factory=dict)


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
