"""The ground truth of one scene over its candidate pool (`SceneTruth`): the surface, the
3D point under each candidate, ground-truth correspondences and tracks (definitions in
`bench.evaluation.metrics`). Shared by the oracle (a selection) and the metrics (scores),
so editing a metric never changes what the oracle selects."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from bench.camera import Camera
from bench.evaluation.groundtruth import GroundTruth, load_dataset_truth, load_ground_truth
from bench.frontend.features import Candidates

CORRESPONDENCE_PX = 3.0
"""Ground-truth correspondence: reprojection within this many pixels."""


def _visible(X: np.ndarray, cam: Camera, gt: GroundTruth) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of X (N, 3) in `cam`, and whether X is visible there by the depth test."""
    uv, z = cam.project(X)
    ok = (
        np.isfinite(uv).all(1)
        & (z > 0)
        & (uv[:, 0] >= 0)
        & (uv[:, 0] < cam.width)
        & (uv[:, 1] >= 0)
        & (uv[:, 1] < cam.height)
    )
    col = np.clip(np.nan_to_num(uv[:, 0]), 0, cam.width - 1).astype(int)
    row = np.clip(np.nan_to_num(uv[:, 1]), 0, cam.height - 1).astype(int)
    zmap = gt.z[row, col]
    ok &= np.isfinite(zmap) & (np.abs(zmap - z) < 0.01 * np.abs(z) + 0.01)
    return uv, ok


@dataclass
class SceneTruth:
    """Ground-truth structures of one render entry and candidate pool, shared by all runs."""

    surface: cKDTree | None
    """Ground-truth surface samples (None: no point accuracy)."""
    cams: list[Camera]
    gts: list[GroundTruth] | None
    """Per-pixel truth (None: a dataset without it)."""
    points: list[np.ndarray] | None
    """Per view: the 3D point under each candidate (NaN on occlusion edges)."""
    pool_xy: list[np.ndarray]
    track: list[np.ndarray] | None
    """Per view: the ground-truth track (connected component) of each candidate."""
    track_views: np.ndarray | None
    """Per track: the number of distinct views it spans."""
    kind: str = "rendered"
    """What truth there is: rendered, per-pixel (a dataset's), point cloud or poses."""

    @property
    def per_pixel(self) -> bool:
        return self.gts is not None

    @staticmethod
    def build(
        cams: list[Camera],
        gts: list[GroundTruth] | None,
        pools: list[Candidates],
        cloud: np.ndarray | None = None,
    ) -> SceneTruth:
        """From per-pixel truth (its single-surface positions are the surface unless a
        point cloud is given), or from a point cloud alone."""
        if gts is None:
            surface = cKDTree(np.asarray(cloud, np.float64)) if cloud is not None else None
            kind = "poses" if cloud is None else "point cloud"
            return SceneTruth(surface, cams, None, None, [c.xy for c in pools], None, None, kind)
        samples = (
            np.concatenate([g.position[g.single_surface] for g in gts]).astype(np.float64)
            if cloud is None
            else np.asarray(cloud, np.float64)
        )
        points = []
        for cam, gt, cand in zip(cams, gts, pools):
            col = np.clip(cand.xy[:, 0].astype(int), 0, cam.width - 1)
            row = np.clip(cand.xy[:, 1].astype(int), 0, cam.height - 1)
            P = gt.position[row, col].astype(np.float64)
            P[~gt.single_surface[row, col]] = np.nan
            points.append(P)
        pool_xy = [c.xy for c in pools]
        track, track_views = _tracks(cams, gts, points, pool_xy)
        return SceneTruth(cKDTree(samples), cams, gts, points, pool_xy, track, track_views)

    def reconstructable(self, min_views: int) -> int | None:
        """Ground-truth tracks spanning at least `min_views` views (None without per-pixel
        truth)."""
        return None if self.track_views is None else int(np.sum(self.track_views >= min_views))

    def correspondences(self, i: int, j: int, ki: np.ndarray, kj: np.ndarray) -> np.ndarray:
        """Whether candidate ki[m] of view i and kj[m] of view j correspond (ground truth)."""

        def one_way(a, b, ka, kb):
            uv, ok = _visible(self.points[a][ka], self.cams[b], self.gts[b])
            return ok & (np.linalg.norm(uv - self.pool_xy[b][kb], axis=1) <= CORRESPONDENCE_PX)

        return one_way(i, j, ki, kj) | one_way(j, i, kj, ki)


def load_truth(source: Path, cams: list[Camera], names: list[str], pools) -> SceneTruth:
    """The truth of a render entry, or whatever truth a dataset folder holds."""
    if (Path(source) / "meta.json").is_file():
        return SceneTruth.build(cams, load_ground_truth(source), pools)
    cloud, gts = load_dataset_truth(source, names, cams)
    truth = SceneTruth.build(cams, gts, pools, cloud)
    if gts is not None:
        truth.kind = "per-pixel"
    return truth


def _tracks(cams, gts, points, pool_xy) -> tuple[list[np.ndarray], np.ndarray]:
    """Connected components of the correspondence graph: per view the component of each
    candidate, and per component the number of views it spans."""
    offsets = np.cumsum([0] + [len(p) for p in points])
    rows, cols = [], []
    for i, j in ((i, j) for i in range(len(cams)) for j in range(len(cams)) if i != j):
        if not len(pool_xy[j]) or not len(points[i]):
            continue
        uv, ok = _visible(np.nan_to_num(points[i]), cams[j], gts[j])
        ok &= np.isfinite(points[i]).all(1)
        d, nn = cKDTree(pool_xy[j]).query(np.where(ok[:, None], uv, 0))
        link = ok & (d <= CORRESPONDENCE_PX)
        rows.append(offsets[i] + np.flatnonzero(link))
        cols.append(offsets[j] + nn[link])
    n = offsets[-1]
    r, c = (np.concatenate(x) if x else np.zeros(0, int) for x in (rows, cols))
    _, label = connected_components(
        coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)), directed=False
    )
    view_of = np.repeat(np.arange(len(points)), np.diff(offsets))
    views = np.zeros(label.max() + 1 if n else 0, int)
    for v in range(len(points)):
        views[np.unique(label[view_of == v])] += 1
    return [label[offsets[v] : offsets[v + 1]] for v in range(len(points))], views
