"""The ground truth of one scene over its candidate pool (`SceneTruth`): the surface, the
3D point under each candidate, ground-truth correspondences and tracks (definitions in
`bench.evaluation.metrics`). Shared by the oracle (a selection) and the metrics (scores),
so editing a metric never changes what the oracle selects."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from bench.camera import Camera
from bench.evaluation.layers import (
    TruthLayers,
    read_dataset_layers,
    read_layers,
    surface_samples,
)
from bench.files import read_meta
from bench.frontend.features import Candidates
from bench.frontend.geometry import saturation_depth
from bench.frontend.views import Source
from bench.vocabulary import RECOMPUTED_TRUTH

CORRESPONDENCE_PX = 3.0
"""Ground-truth correspondence: reprojection within this many pixels."""
COVISIBLE_DEG = 60.0
"""Without tracks to count, two views are covisible when their viewing directions are at
most this far apart (SIFT's matching repeatability falls below a fifth past about 60
degrees of viewpoint change: Mikolajczyk et al., IJCV 2005) and their view frustums
overlap."""
SCALE_CHANGE = 2.0
"""Without tracks to count or optical axes that meet in both images (views on a path, or
driving forward), two views are covisible when the point at the working distance on one's
optical axis lies inside the other's image at most this factor nearer or farther (one
octave of SIFT's scale space); the working distance is the one the rig's geometry takes
without points (`bench.frontend.geometry.saturation_depth` of the median distance from a
view to its nearest view)."""
BLOCK = 16384
"""Surface samples per block of `Surface`."""


class Surface:
    """Ground-truth surface samples, and the exact distance from points to the nearest one.

    One k-d tree over all samples is slow far from the surface: its cells reach into the
    empty space in front of it, so a point 10 units away visits much of the tree (1,000
    points 5-15 units away took 2.9 s, against 4 ms near the surface). Here the samples are
    split into blocks of neighbouring samples, each with its own k-d tree and tight bounding
    box; a point visits the blocks in the order of their box's distance and stops at the
    first box farther than its nearest sample so far. The distances are a single tree's, to
    the last bit (the same arithmetic on the same nearest sample). The last query's answer
    is kept: a tri model's scores and its `point_errors.csv` ask for the same points."""

    def __init__(self, samples: np.ndarray):
        samples = np.asarray(samples, np.float64).reshape(-1, 3)
        blocks = []
        if len(samples):
            stack = [cKDTree(samples, leafsize=BLOCK, balanced_tree=False).tree]
            while stack:  # the leaves of a coarse tree: blocks of neighbouring samples
                node = stack.pop()
                if node.split_dim == -1:
                    blocks.append(samples[node.indices])
                else:
                    stack += [node.lesser, node.greater]
        self.trees = [cKDTree(b, balanced_tree=False) for b in blocks]
        self.lo = np.array([b.min(0) for b in blocks]).reshape(-1, 3)
        self.hi = np.array([b.max(0) for b in blocks]).reshape(-1, 3)
        self._last: tuple[bytes, np.ndarray] | None = None

    def distances(self, X: np.ndarray) -> np.ndarray:
        """Distance from each point (N, 3) to the nearest sample (inf without samples)."""
        X = np.ascontiguousarray(X, np.float64).reshape(-1, 3)
        key = X.tobytes()
        if self._last is None or self._last[0] != key:
            self._last = (key, self._nearest(X))
        return self._last[1].copy()

    def _nearest(self, X: np.ndarray, chunk: int = 1024) -> np.ndarray:
        best = np.full(len(X), np.inf)
        for start in range(0, len(X) if self.trees else 0, chunk):
            x, near = X[start : start + chunk], best[start : start + chunk]
            gap = np.maximum(self.lo - x[:, None], 0) + np.maximum(x[:, None] - self.hi, 0)
            bound = np.sqrt(np.einsum("nbk,nbk->nb", gap, gap))  # to each block's box
            order = np.argsort(bound, 1)
            bound = np.take_along_axis(bound, order, 1)
            for k in range(order.shape[1]):
                # a margin of 1e-9: the box bound and the tree round in their own ways
                pts = np.flatnonzero(bound[:, k] <= near * (1 + 1e-9))
                if not len(pts):
                    break
                for b in np.unique(order[pts, k]):
                    sel = pts[order[pts, k] == b]
                    near[sel] = np.minimum(near[sel], self.trees[b].query(x[sel])[0])
        return best


def _visible(X: np.ndarray, cam: Camera, gt: TruthLayers) -> tuple[np.ndarray, np.ndarray]:
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

    surface: Surface | None
    """Ground-truth surface samples (None: no point accuracy)."""
    cams: list[Camera]
    gts: list[TruthLayers] | None
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
    seen: list[np.ndarray] | None = None
    """Per view, the ids of the 3D points a dataset's model observes there (None: none)."""
    reach: list[np.ndarray] | None = None
    """Per view, the distance `CORRESPONDENCE_PX` spans at each candidate's point (its
    depth / focal length x 3 px): the radius of the tracks (`track_points`)."""

    @property
    def per_pixel(self) -> bool:
        return self.gts is not None

    @staticmethod
    def build(
        cams: list[Camera],
        gts: list[TruthLayers] | None,
        pools: list[Candidates],
        cloud: np.ndarray | None = None,
    ) -> SceneTruth:
        """From per-pixel truth (its single-surface positions are the surface unless a
        point cloud is given), or from a point cloud alone."""
        if gts is None:
            surface = Surface(cloud) if cloud is not None else None
            kind = "poses" if cloud is None else "point cloud"
            return SceneTruth(surface, cams, None, None, [c.xy for c in pools], None, None, kind)
        samples = surface_samples(gts) if cloud is None else cloud
        points = []
        for cam, gt, cand in zip(cams, gts, pools):
            col = np.clip(cand.xy[:, 0].astype(int), 0, cam.width - 1)
            row = np.clip(cand.xy[:, 1].astype(int), 0, cam.height - 1)
            P = gt.position[row, col].astype(np.float64)
            P[~gt.single_surface[row, col]] = np.nan
            points.append(P)
        pool_xy = [c.xy for c in pools]
        track, track_views = _tracks(cams, gts, points, pool_xy)
        reach = [
            CORRESPONDENCE_PX * cam.to_camera(np.nan_to_num(p))[:, 2] / cam.fx
            for cam, p in zip(cams, points)
        ]
        return SceneTruth(
            Surface(samples), cams, gts, points, pool_xy, track, track_views, reach=reach
        )

    def reconstructable(self, min_views: int) -> int | None:
        """Ground-truth tracks spanning at least `min_views` views (None without per-pixel
        truth)."""
        return None if self.track_views is None else int(np.sum(self.track_views >= min_views))

    def track_points(self, min_views: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The reconstructable tracks (spanning at least `min_views` views) as 3D points: each
        track's mean ground-truth point over its candidates, and the distance in which a
        reconstructed point is that track's (`CORRESPONDENCE_PX` at the track's depth in
        its views); None without per-pixel truth."""
        if self.track is None:
            return None
        label = np.concatenate(self.track)
        P = np.concatenate(self.points)
        px = np.concatenate(self.reach)
        keep = (self.track_views[label] >= min_views) & np.isfinite(P).all(1)
        tracks, member = np.unique(label[keep], return_inverse=True)
        count = np.bincount(member, minlength=len(tracks))[:, None]
        mean = np.stack([np.bincount(member, P[keep][:, k], len(tracks)) for k in range(3)], 1)
        radius = np.bincount(member, px[keep], len(tracks)) / count[:, 0]
        return mean / count, radius

    def shared_pairs(self, min_shared: int) -> list[tuple[int, int]] | None:
        """The pairs of views (i < j) whose candidates share at least `min_shared`
        ground-truth tracks (ground-truth points seen by both; None without per-pixel
        truth)."""
        if self.track is None:
            return None
        seen = [np.unique(t) for t in self.track]
        return [
            (i, j)
            for i, j in combinations(range(len(seen)), 2)
            if len(np.intersect1d(seen[i], seen[j], assume_unique=True)) >= min_shared
        ]

    def covisible_pairs(self, min_shared: int) -> tuple[list[tuple[int, int]], str]:
        """The pairs of views (i < j) that see the same surface, and by which rule: sharing
        at least `min_shared` ground-truth tracks (per-pixel truth), else at least as many
        of a dataset model's points, else viewing directions within `COVISIBLE_DEG` with
        overlapping frustums (poses alone)."""
        if self.track is not None:
            return self.shared_pairs(min_shared), f"ground-truth tracks >= {min_shared}"
        return covisible_pairs(self.cams, self.seen, min_shared)

    def correspondences(self, i: int, j: int, ki: np.ndarray, kj: np.ndarray) -> np.ndarray:
        """Whether candidate ki[m] of view i and kj[m] of view j correspond (ground truth)."""

        def one_way(a, b, ka, kb):
            uv, ok = _visible(self.points[a][ka], self.cams[b], self.gts[b])
            return ok & (np.linalg.norm(uv - self.pool_xy[b][kb], axis=1) <= CORRESPONDENCE_PX)

        return one_way(i, j, ki, kj) | one_way(j, i, kj, ki)


def scene_truth(source: Path, cams: list[Camera], names: list[str], pools) -> SceneTruth:
    """The truth of a render entry, or whatever truth a dataset folder holds (with the
    points its model observes in each view)."""
    if Source.kind(source) == "render":
        truth = SceneTruth.build(cams, read_layers(source), pools)
        if "reference" in read_meta(source):  # pixels shipped, layers by the AOV pass here
            truth.kind = RECOMPUTED_TRUTH
        return truth
    cloud, gts = read_dataset_layers(source, names, cams)
    truth = SceneTruth.build(cams, gts, pools, cloud)
    seen = Source.of(source).seen()
    truth.seen = [seen.get(n, np.zeros(0, np.int64)) for n in names]
    if gts is not None:
        truth.kind = "per-pixel"
    return truth


def covisible_pairs(
    cams: list[Camera], seen: list[np.ndarray] | None, min_shared: int
) -> tuple[list[tuple[int, int]], str]:
    """The pairs of views (i < j) that see the same surface by a dataset model alone, and by
    which rule: sharing at least `min_shared` of the model's points (`seen`: those each
    view observes) where it has points, else viewing directions within `COVISIBLE_DEG`
    with overlapping frustums (poses alone, `_facing`)."""
    pairs = combinations(range(len(cams)), 2)
    if seen is not None and any(len(s) for s in seen):
        shared = [(i, j) for i, j in pairs if len(np.intersect1d(seen[i], seen[j])) >= min_shared]
        return shared, f"model tracks >= {min_shared}"
    depth = _working_distance(cams)
    facing = [(i, j) for i, j in pairs if _facing(cams[i], cams[j], depth)]
    return facing, f"viewing directions within {COVISIBLE_DEG:g} deg, frustums overlap"


def _working_distance(cams: list[Camera]) -> float:
    """The working distance of views without points (`SCALE_CHANGE`)."""
    if len(cams) < 2:
        return 1.0
    centres = np.array([c.center for c in cams])
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.diag([np.inf] * len(cams))
    return saturation_depth(float(np.median(gaps.min(1))))


def _facing(a: Camera, b: Camera, depth: float) -> bool:
    """Viewing directions within `COVISIBLE_DEG`, and frustums that overlap: the point
    where the two optical axes pass closest lies in front of both cameras and inside both
    images (axes that meet, as on a ring around an object); else (axes parallel or apart,
    as on a path or driving forward) the point at the working distance `depth` on one's
    axis lies inside the other's image, within `SCALE_CHANGE` of that distance."""
    da, db = a.R[2], b.R[2]  # optical axes (world)
    if np.degrees(np.arccos(np.clip(da @ db, -1, 1))) > COVISIBLE_DEG:
        return False
    w = a.center - b.center
    cross = np.cross(da, db)
    if np.linalg.norm(cross) >= 1e-3:  # closest points of the axes: a.c + s da, b.c + u db
        m = np.array([[da @ da, -(da @ db)], [da @ db, -(db @ db)]])
        s, u = np.linalg.solve(m, [-(w @ da), -(w @ db)])
        P = (a.center + s * da + b.center + u * db) / 2
        if _inside(a, P) and _inside(b, P):
            return True
    for near, far in ((a, b), (b, a)):
        X = near.center + depth * near.R[2]
        z = float(far.to_camera(X[None])[0, 2])
        if _inside(far, X) and max(z / depth, depth / z) <= SCALE_CHANGE:
            return True
    return False


def _inside(cam: Camera, P: np.ndarray) -> bool:
    """Whether the point P lies in front of the camera and inside its image."""
    uv, z = cam.project(P[None])
    return bool(z[0] > 0 and 0 <= uv[0, 0] < cam.width and 0 <= uv[0, 1] < cam.height)


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
