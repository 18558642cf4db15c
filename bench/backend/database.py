"""The COLMAP database's first rows and COLMAP's log: the cameras and images of a set of
views, shared by every database the back end writes (`bench.backend.reconstruction`) and
by stock COLMAP's extraction (`bench.backend.extraction`), which depend on nothing else of
the back end."""

from __future__ import annotations

from contextlib import contextmanager

import pycolmap

from bench.camera import Camera
from bench.twoview import colmap_camera


@contextmanager
def quiet_colmap():
    """COLMAP's log silenced while the back end calls it (its failures become recorded
    reasons), and the caller's level restored afterwards."""
    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 3
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


def camera_ids(cams: list[Camera]) -> list[int]:
    """COLMAP camera id of each view: views with the same intrinsics share one camera."""
    seen: dict[tuple, int] = {}
    return [
        seen.setdefault((c.width, c.height, c.fx, c.fy, c.cx, c.cy), len(seen) + 1) for c in cams
    ]


def colmap_cameras(cams: list[Camera]) -> dict[int, pycolmap.Camera]:
    out = {}
    for cid, cam in zip(camera_ids(cams), cams):
        out.setdefault(cid, colmap_camera(cam, cid))
    return out


def write_images(db: pycolmap.Database, cams: list[Camera], names: list[str]) -> None:
    """The cameras (shared where the intrinsics are) and images (ids 1..n) of a database."""
    for cam in colmap_cameras(cams).values():
        db.write_camera(cam, use_camera_id=True)
    for k, (cid, name) in enumerate(zip(camera_ids(cams), names)):
        db.write_image(pycolmap.Image(name=name, camera_id=cid, image_id=k + 1), use_image_id=True)
