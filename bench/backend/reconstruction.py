"""Reconstruction on COLMAP (pycolmap) from the selected keypoints and verified matches.

Two tasks share the database and the matches:

Known-pose triangulation (task `tri`): a COLMAP database holding exactly the selected
keypoints and the verified matches (each pair with the configuration its verification
found), and `pycolmap.triangulate_points` on a reconstruction whose poses are the rig's
(poses and intrinsics held fixed; points refined by COLMAP's bundle adjustment).

Track protocols (the same for every policy):

* `multiview` (the headline): COLMAP's default point triangulation, which ignores
  two-view tracks, keeps its 1.5 degree minimum triangulation angle and 4 px reprojection
  filters; then every point whose final track has fewer than three views is removed, so
  each point is checked by at least a third view.
* `twoview`: the same with two-view tracks kept (COLMAP drops them by default); reported
  in its own table only, because a two-view track cannot be checked by a third view and
  nearly all gross outliers come from such tracks.

Structure from motion (task `sfm`): COLMAP's incremental mapper on the same database,
with the intrinsics known and fixed (no focal length, principal point or distortion
refinement) and the poses unknown; the model with the most registered views is kept.
The rig's poses are never read for it. Where COLMAP's first-pair tests stop it (fewer than
two views registered), the mapper starts once more from a forward-motion first pair
(`FORWARD_START`): a capture that moves along its optical axis (a car, a survey drone, a
corridor robot) gives first pairs of small angle whose motion lies along the axis, which
COLMAP's defaults refuse (docs/datasets.md, "A forward-moving set"). The track protocol
applies to its triangulation too: `multiview` is COLMAP's default mapper (two-view tracks
ignored; so a scene seen by two views alone cannot be mapped), `twoview` keeps them.

The triangulator and the mapper are seeded and single-threaded, so a run is reproducible.
Neither reads the images: COLMAP reads them only to colour the points, which no metric
reads, and that was most of a call (a Herz-Jesu bag's mapping, 6-megapixel views: 0.74 s
with the colours, 0.10 s without; every pose and point the same). The mapper is told not
to (`extract_colors`), and both are given an empty folder for the images (the
triangulator colours whatever it is told).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from bench.backend.database import camera_ids, colmap_cameras, quiet_colmap, write_images
from bench.backend.matching import BackendConfig, PairMatches
from bench.camera import Camera
from bench.vocabulary import PROTOCOLS


@dataclass
class Reconstruction:
    """A reconstruction task's result: a COLMAP model, or the reason there is none."""

    model: pycolmap.Reconstruction | None
    failure: str | None
    seconds: float


def colmap_descriptors(desc: np.ndarray) -> np.ndarray:
    """SIFT descriptors in COLMAP's format: L1-root normalised (COLMAP's default), then
    512 x value rounded and clipped to uint8."""
    d = np.abs(np.asarray(desc, np.float64))
    d = np.sqrt(d / np.maximum(d.sum(1, keepdims=True), 1e-12))
    return np.clip(np.round(512 * d), 0, 255).astype(np.uint8)


def write_database(
    path: Path,
    cams: list[Camera],
    names: list[str],
    xy: list[np.ndarray],
    pairs: list[PairMatches] = (),
    descriptors: list[np.ndarray] | None = None,
) -> None:
    """A COLMAP database: cameras, images, keypoints (and their descriptors, given SIFT
    ones), tentative matches and each verified pair with the configuration its
    verification found (unverified pairs get no two-view geometry)."""
    db = pycolmap.Database.open(str(path))
    try:
        write_images(db, cams, names)
        for k in range(len(names)):
            db.write_keypoints(k + 1, xy[k].astype(np.float32).reshape(-1, 2))
            if descriptors is not None:
                db.write_descriptors(
                    k + 1,
                    pycolmap.FeatureDescriptors(
                        pycolmap.FeatureExtractorType.SIFT, colmap_descriptors(descriptors[k])
                    ),
                )
        for p in pairs:
            db.write_matches(p.i + 1, p.j + 1, p.tentative.astype(np.uint32))
            if len(p.verified):
                tvg = pycolmap.TwoViewGeometry()
                tvg.inlier_matches = p.verified.astype(np.uint32)
                tvg.config = pycolmap.TwoViewGeometryConfiguration.__members__[p.config]
                db.write_two_view_geometry(p.i + 1, p.j + 1, tvg)
    finally:
        db.close()


def known_pose_model(
    cams: list[Camera], names: list[str], xy: list[np.ndarray]
) -> pycolmap.Reconstruction:
    """A COLMAP model with the rig's intrinsics and poses, each image holding its selected
    keypoints (all of them, so the export is a complete record of the selection)."""
    rec = pycolmap.Reconstruction()
    for cam in colmap_cameras(cams).values():
        rec.add_camera_with_trivial_rig(cam)
    for k, (cam, cid, name) in enumerate(zip(cams, camera_ids(cams), names)):
        image = pycolmap.Image(
            name=name,
            keypoints=xy[k].astype(np.float64).reshape(-1, 2),
            camera_id=cid,
            image_id=k + 1,
        )
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(cam.R), cam.t))
    return rec


def drop_short_tracks(model: pycolmap.Reconstruction, min_views: int) -> None:
    """Remove every point whose track has fewer than `min_views` distinct views."""
    for pid, point in list(model.points3D.items()):
        if len({el.image_id for el in point.track.elements}) < min_views:
            model.delete_point3D(pid)


def triangulate(
    cams: list[Camera],
    names: list[str],
    xy: list[np.ndarray],
    pairs: list[PairMatches],
    cfg: BackendConfig,
    protocol: str = "multiview",
) -> pycolmap.Reconstruction:
    """Triangulate the verified tracks with the rig's known poses through COLMAP, under a
    track protocol (see the module docstring)."""
    work = Path(tempfile.mkdtemp(prefix="bench-colmap-"))
    try:
        write_database(work / "database.db", cams, names, xy, pairs)
        rec = known_pose_model(cams, names, xy)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.triangulation.ignore_two_view_tracks = PROTOCOLS[protocol] > 2
        opts.triangulation.min_angle = cfg.min_tri_angle
        opts.mapper.filter_min_tri_angle = cfg.min_tri_angle
        opts.triangulation.random_seed = cfg.seed
        opts.random_seed = cfg.seed
        opts.num_threads = 1
        (work / "out").mkdir()
        (work / "no-images").mkdir()  # the points' colours only (module docstring)
        with quiet_colmap():
            model = pycolmap.triangulate_points(
                rec, work / "database.db", work / "no-images", work / "out", options=opts
            )
        drop_short_tracks(model, PROTOCOLS[protocol])
        return model
    finally:
        shutil.rmtree(work, ignore_errors=True)


def known_pose_task(
    cams: list[Camera],
    names: list[str],
    xy: list[np.ndarray],
    pairs: list[PairMatches],
    cfg: BackendConfig,
    protocol: str,
) -> Reconstruction:
    """Task `tri`: triangulate with the known poses; failures are recorded, never raised."""
    t = time.perf_counter()
    if sum(len(p.verified) for p in pairs) == 0:
        return Reconstruction(None, "no pair of views has verified matches", 0.0)
    try:
        model = triangulate(cams, names, xy, pairs, cfg, protocol)
    except Exception as e:  # COLMAP failures become a recorded reason
        return Reconstruction(
            None, f"triangulation failed: {type(e).__name__}: {e}", time.perf_counter() - t
        )
    failure = None if model.num_points3D() > 0 else "no track could be triangulated"
    return Reconstruction(model, failure, time.perf_counter() - t)


FORWARD_START = {"init_min_tri_angle": 2.0, "init_max_forward_motion": 1.0}
"""The mapper's options of the second start, where COLMAP's defaults (16 degrees, which it
relaxes to 8 and 4 by itself; a first pair moving within 18 degrees of the optical axis
refused) register fewer than two views: the first pair may move along the axis, at 2
degrees of triangulation angle (relaxed by COLMAP in the same way, to 1 and 0.5: a pair of
0.65 degrees is mapped, tests/test_backend.py). Never tried where the defaults map."""


def fixed_intrinsics_options(
    cfg: BackendConfig, protocol: str, forward: bool = False
) -> pycolmap.IncrementalPipelineOptions:
    """COLMAP's incremental mapper with known, fixed intrinsics under a track protocol;
    seeded, one thread; with `forward`, the first pair of `FORWARD_START`."""
    opts = pycolmap.IncrementalPipelineOptions()
    if forward:
        for name, value in FORWARD_START.items():
            setattr(opts.mapper, name, value)
    opts.triangulation.ignore_two_view_tracks = PROTOCOLS[protocol] > 2
    opts.ba_refine_focal_length = False
    opts.ba_refine_principal_point = False
    opts.ba_refine_extra_params = False
    opts.random_seed = cfg.seed
    opts.num_threads = 1
    opts.extract_colors = False  # the points' colours only (module docstring)
    return opts


def _incremental(database: Path, opts) -> pycolmap.Reconstruction | str:
    """COLMAP's incremental mapper once: the model with the most registered views (two at
    least), or why there is none."""
    work = Path(tempfile.mkdtemp(prefix="bench-map-"))
    try:
        (work / "out").mkdir()
        (work / "no-images").mkdir()  # the points' colours only (module docstring)
        with quiet_colmap():
            models = pycolmap.incremental_mapping(
                database, work / "no-images", work / "out", options=opts
            )
    except Exception as e:  # COLMAP failures become a recorded reason
        return f"mapping failed: {type(e).__name__}: {e}"
    finally:
        shutil.rmtree(work, ignore_errors=True)
    best = max(models.values(), key=lambda m: m.num_reg_images(), default=None)
    if best is None or best.num_reg_images() < 2:
        return f"the mapper registered {0 if best is None else best.num_reg_images()} view(s)"
    return best


def map_database(database: Path, cfg: BackendConfig, protocol: str) -> Reconstruction:
    """Incremental mapping of a COLMAP database under a track protocol, from COLMAP's first
    pair, else from a forward-motion one (`FORWARD_START`); the largest model (points of
    shorter tracks than the protocol allows removed), or why there is none."""
    t = time.perf_counter()
    best = _incremental(database, fixed_intrinsics_options(cfg, protocol))
    if isinstance(best, str):
        forward = _incremental(database, fixed_intrinsics_options(cfg, protocol, True))
        best = best if isinstance(forward, str) else forward  # the first start's reason
    if isinstance(best, str):
        return Reconstruction(None, best, time.perf_counter() - t)
    drop_short_tracks(best, PROTOCOLS[protocol])
    return Reconstruction(best, None, time.perf_counter() - t)


def mapping_task(
    cams: list[Camera],
    names: list[str],
    xy: list[np.ndarray],
    pairs: list[PairMatches],
    cfg: BackendConfig,
    protocol: str = "multiview",
) -> Reconstruction:
    """Task `sfm`: incremental mapping from the selected keypoints and verified matches,
    intrinsics known and fixed, poses unknown; failures are recorded, never raised."""
    if sum(len(p.verified) for p in pairs) == 0:
        return Reconstruction(None, "no pair of views has verified matches", 0.0)
    work = Path(tempfile.mkdtemp(prefix="bench-sfm-"))
    try:
        write_database(work / "database.db", cams, names, xy, pairs)
        return map_database(work / "database.db", cfg, protocol)
    finally:
        shutil.rmtree(work, ignore_errors=True)
