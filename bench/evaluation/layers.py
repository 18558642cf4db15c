"""Reading ground truth: a render entry's layers, or a dataset's. Imported only by the
evaluation and the commands that write datasets.

A dataset (`DIR/images/`, `DIR/sparse/`) may hold, besides the poses of its model:

* `DIR/ground_truth/points.ply`: a ground-truth point cloud (vertex x, y, z; ASCII or
  binary little-endian PLY): the surface that point accuracy is measured against;
* `DIR/ground_truth/<image name>.npz`: per-pixel truth of one image, `z` (HxW z-depth,
  NaN where unknown or on an occlusion edge) and optionally `position` (HxWx3 world
  points, NaN off the surface or on an occlusion edge; else back-projected from z): what
  match precision, ground-truth tracks, the completeness metrics and the oracle need.
  `bench export` writes both.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.camera import Camera
from bench.render.entry import entry_meta, truth_name


@dataclass(frozen=True)
class TruthLayers:
    """One view's ground truth (float32 HxW or HxWx3; NaN / -1 where nothing was hit)."""

    range: np.ndarray
    z: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    shape_index: np.ndarray

    @property
    def single_surface(self) -> np.ndarray:
        """Pixels covered by one surface (an integral shape index): their layers are exact,
        while pixels on an occlusion edge average two surfaces."""
        return (self.shape_index >= 0) & (self.shape_index == np.round(self.shape_index))


def read_layers(entry: Path) -> list[TruthLayers]:
    """The ground-truth layers of every view of a render entry."""
    entry = Path(entry)
    try:
        n = len(entry_meta(entry)["cameras"])
        out = []
        for v in range(n):
            with np.load(entry / truth_name(v)) as z:
                out.append(
                    TruthLayers(
                        *(z[k] for k in ("range", "z", "position", "normal", "shape_index"))
                    )
                )
        return out
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as e:
        raise BenchError(f"cannot read the ground truth of {entry}: {e}") from e


def surface_samples(gts: list[TruthLayers]) -> np.ndarray:
    """The ground-truth surface as points: every view's single-surface positions (Nx3)."""
    return np.concatenate([g.position[g.single_surface] for g in gts])


TRUTH_DIR = "ground_truth"
CLOUD = "points.ply"
_PLY_TYPES = {
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
    "uchar": "u1",
    "uint8": "u1",
    "char": "i1",
    "int8": "i1",
    "short": "i2",
    "ushort": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
}


def read_ply_points(path: Path) -> np.ndarray:
    """The x, y, z of the vertices of a PLY file (ASCII or binary little-endian)."""
    try:
        data = Path(path).read_bytes()
        end = data.index(b"end_header") + len(b"end_header")
        end = data.index(b"\n", end) + 1
        header = data[:end].decode("ascii").splitlines()
        fmt = header[1].split()[1]
        props, n, in_vertex = [], 0, False
        for line in header:
            w = line.split()
            if w[:1] == ["element"]:
                in_vertex = w[1] == "vertex"
                n = int(w[2]) if in_vertex else n
            elif w[:1] == ["property"] and in_vertex:
                if w[1] == "list":
                    raise ValueError("list properties in the vertex element")
                props.append((w[2], "<" + _PLY_TYPES[w[1]]))
        if fmt == "ascii":
            rows = data[end:].decode("ascii").split("\n")[:n]
            table = np.array([r.split()[: len(props)] for r in rows], float)
            cols = {name: table[:, k] for k, (name, _) in enumerate(props)}
        elif fmt == "binary_little_endian":
            cols = np.frombuffer(data, dtype=np.dtype(props), count=n, offset=end)
        else:
            raise ValueError(f"unsupported PLY format {fmt}")
        return np.stack([np.asarray(cols[k], float) for k in "xyz"], 1)
    except (OSError, ValueError, KeyError, IndexError) as e:
        raise BenchError(f"cannot read the point cloud {path}: {e}") from e


def write_ply_points(path: Path, X: np.ndarray) -> None:
    """A binary little-endian PLY of points (N, 3) as float32."""
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(X)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    Path(path).write_bytes(header.encode() + np.asarray(X, "<f4").tobytes())


def has_pixel_truth(root: Path, names: list[str]) -> bool:
    """Whether every image of a dataset has its per-pixel truth file."""
    return all((Path(root) / TRUTH_DIR / f"{n}.npz").is_file() for n in names)


def read_dataset_layers(
    root: Path, names: list[str], cams: list[Camera]
) -> tuple[np.ndarray | None, list[TruthLayers] | None]:
    """A dataset's point cloud and per-pixel truth, each None where the dataset has none
    (per-pixel truth counts only when every image has it)."""
    folder = Path(root) / TRUTH_DIR
    cloud = read_ply_points(folder / CLOUD) if (folder / CLOUD).is_file() else None
    if not has_pixel_truth(root, names):
        return cloud, None
    files = [folder / f"{n}.npz" for n in names]
    gts = []
    for f, cam in zip(files, cams):
        try:
            with np.load(f) as z:
                depth = z["z"].astype(np.float32)
                pos = z["position"] if "position" in z.files else None
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as e:
            raise BenchError(f"cannot read the per-pixel ground truth {f}: {e}") from e
        if depth.shape != (cam.height, cam.width):
            raise BenchError(f"{f}: z is {depth.shape}, the image {cam.height}x{cam.width}")
        if pos is None:
            v, u = np.mgrid[: cam.height, : cam.width] + 0.5
            rays = cam.rays(np.c_[u.ravel(), v.ravel()]).reshape(cam.height, cam.width, 3)
            along = rays @ cam.R[2]  # z of a unit ray
            pos = cam.center + rays * (depth / along)[..., None]
        index = np.where(np.isfinite(pos).all(-1), 0.0, -1.0).astype(np.float32)
        gts.append(TruthLayers(depth, depth, pos.astype(np.float32), pos * np.nan, index))
    return cloud, gts
