"""Pinhole cameras in the OpenCV/COLMAP convention, and the rig's COLMAP text export.

Pose is `cam_from_world` (R, t): x right, y down, z forward. Pixel (0, 0)'s centre is
at (0.5, 0.5). Conversion to Mitsuba's camera frame happens only in `bench.render.entry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Camera:
    """One calibrated view: intrinsics and the `cam_from_world` pose."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    R: np.ndarray
    """3x3 rotation, world to camera."""
    t: np.ndarray
    """Translation, world to camera."""

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return -self.R.T @ self.t

    def to_camera(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) to camera coordinates (N, 3)."""
        return X @ self.R.T + self.t

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) to pixels (N, 2) in COLMAP's convention, and their z-depth."""
        Xc = self.to_camera(X)
        z = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.fx * Xc[:, 0] / z + self.cx, self.fy * Xc[:, 1] / z + self.cy], 1)
        return uv, z

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Unit viewing directions (N, 3) in world coordinates through pixels (N, 2)."""
        d = np.stack(
            [(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy, np.ones(len(uv))], 1
        )
        d = d @ self.R  # camera to world: R^T d, written for row vectors
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def look_at(eye, target, up=(0.0, 0.0, 1.0), width=640, height=480, fov_x_deg=60.0) -> Camera:
    """A camera at `eye` looking at `target`, image y pointing away from `up`."""
    eye, target, up = (np.asarray(v, float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    f = 0.5 * width / math.tan(math.radians(fov_x_deg) / 2)
    return Camera(width, height, f, f, width / 2, height / 2, R, -R @ eye)


def write_colmap_rig(cameras: list[Camera], directory: Path, names: list[str]) -> None:
    """Write `cameras.txt` (one shared PINHOLE camera) and `images.txt` (no points)."""
    c0 = cameras[0]
    for c in cameras:
        if (c.width, c.height, c.fx, c.fy, c.cx, c.cy) != (
            c0.width,
            c0.height,
            c0.fx,
            c0.fy,
            c0.cx,
            c0.cy,
        ):
            raise ValueError("the rig export assumes one shared intrinsic camera")
    directory = Path(directory)
    (directory / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n"
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        f"1 PINHOLE {c0.width} {c0.height} {c0.fx!r} {c0.fy!r} {c0.cx!r} {c0.cy!r}\n"
    )
    lines = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
    ]
    for i, (c, name) in enumerate(zip(cameras, names), start=1):
        qx, qy, qz, qw = Rotation.from_matrix(c.R).as_quat()
        vals = " ".join(repr(float(v)) for v in (qw, qx, qy, qz, *c.t))
        lines += [f"{i} {vals} 1 {name}", ""]
    (directory / "images.txt").write_text("\n".join(lines) + "\n")
