"""The geometry between views that the signals read: from the calibration's poses
(`rig_geometry`), or estimated from the images alone (`image_geometry`), whichever the
task grants (`Task.grant`): `view_geometry` takes the rig's when every view is posed. A
`Geometry` gives, per view, the views that overlap it, ambiguity's nearest views and, for
each overlapping pair, a two-camera frame (`pair_frame`) from which the epipolar geometry
and the parallax are computed. From the images, a first pass matches the strongest
candidates of every pair and COLMAP's calibrated two-view geometry estimates their
relative pose (`bench.twoview`); a photograph's unknown focal length is estimated first
where the images determine it (`estimate_focal`). A pair whose geometry cannot be
estimated does not overlap (a value, never an error). The details, and what they measure,
are in docs/protocol.md ("The geometry the signals read").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import pycolmap

from bench.camera import Camera
from bench.console import log
from bench.frontend.features import Candidates, descriptor_distances, tentative_matches
from bench.frontend.pools import strongest_first
from bench.frontend.views import View
from bench.twoview import two_view_geometry, verification_options

RIG, IMAGES = "rig", "images"
"""The two sources of geometry: the calibration's poses, or the images alone."""
PARALLAX_SATURATION_DEG = 10.0
EPIPOLAR_PX = 3.0
EPIPOLAR_RATIO = 0.8
DEPTH_CANDIDATES = 150
DEPTH_MIN_POINTS = 10
AMBIGUITY_VIEWS = 2
MIN_SUPPORT = 15
"""First-pass matches that an estimated relative pose must explain for two views to
overlap (COLMAP's `min_num_inliers`)."""
FIRST_PASS_RATIO = 0.8
FIRST_PASS_MAX_ERROR = 1.0
"""RANSAC and support threshold of the first pass, px: tighter than COLMAP's default 4 px,
which gave relative rotations 1.5 degrees off the rig's (median, table seed 0) against 0.7."""
FIRST_PASS_TRIALS = 1000
"""RANSAC trials of the first pass (COLMAP's default 10000): enough for an inlier ratio of
0.4 at 99.9% confidence; a pair with fewer inliers than that is left out."""
RANSAC_SEED = 0
FOCAL_FACTORS = np.geomspace(0.3, 3.0, 241)
"""The focal lengths `estimate_focal` tries, x max(width, height): about 1% apart."""
FOCAL_MIN_PAIRS = 2
FOCAL_STEPS = (1.05, 1.02)
"""The factors by which `estimate_focal` refines its estimate (coarse, then fine)."""
CRITICAL = (
    "views whose optical axes meet, as on a ring around an object, or lie along the motion, "
    "as driving forward, leave it undetermined"
)
"""The motions that do not determine the focal length (`estimate_focal` says so): measured
on the Middlebury rings and on `kitti-seq2` (`benchmarks/focal_estimate.py`, retired:
`git show 3c3e1bd:benchmarks/focal_estimate.py`; every window of 3 to 8 frames left
undetermined, 1.0 to 1.5 times the matches at 1.5 x off)."""
FOCAL_OFF, FOCAL_PEAK = 1.5, 1.5
"""An estimate is determined when its calibrated relative poses explain at least FOCAL_PEAK
times the matches they explain at FOCAL_OFF times and 1 / FOCAL_OFF times it (measured on
the shared sets, `benchmarks/focal_estimate.py`, retired, above: 1.8 to 5.6 on subsets of
Herz-Jesu, at most 1.03 on the Middlebury rings, whose optical axes meet)."""


@dataclass(frozen=True)
class SignalConfig:
    """Settings of the quality signals."""

    depth_prior: float | None = None
    """Working distance in scene units at which parallax and overlap are judged from the
    poses; None (the default) estimates it per view from the calibration and sparse
    epipolar matches. Geometry estimated from the images has no scene units and ignores it."""
    first_pass: int = 512
    """Geometry from the images: the strongest candidates per view (by detector response)
    matched and verified between every pair of views."""


def fundamental(a: Camera, b: Camera) -> np.ndarray:
    """F with x_b^T F x_a = 0 for pixels (COLMAP convention) of one point in views a and b."""
    R = b.R @ a.R.T
    t = b.t - R @ a.t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return np.linalg.inv(b.K).T @ tx @ R @ np.linalg.inv(a.K)


def epipolar_distances(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """(Na, Nb): the larger of the two point-to-epipolar-line distances in pixels."""
    ha, hb = np.c_[xa, np.ones(len(xa))], np.c_[xb, np.ones(len(xb))]
    la, lb = ha @ F.T, hb @ F  # lines in b of points of a; lines in a of points of b
    num = np.abs((la @ hb.T).astype(np.float32))
    inv_a = 1 / np.maximum(np.hypot(la[:, 0], la[:, 1]), 1e-12)
    inv_b = 1 / np.maximum(np.hypot(lb[:, 0], lb[:, 1]), 1e-12)
    return num * np.maximum(inv_a[:, None], inv_b[None, :]).astype(np.float32)


def epipolar_matches(
    D2: np.ndarray, E: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ratio-passing matches along epipolar lines, both ways: (passes of a, best of a,
    passes of b, best of b) from squared descriptor distances D2 and epipolar distances E."""
    Dm = np.where(E <= EPIPOLAR_PX, D2, np.float32(np.inf))

    def one_way(M):
        rows = np.arange(len(M))
        if M.shape[1] < 1:
            return np.zeros(len(M), bool), np.zeros(len(M), int)
        best = M.argmin(1)
        d1 = M[rows, best]
        M[rows, best] = np.inf
        d2 = M.min(1)
        M[rows, best] = d1
        return np.isfinite(d1) & (d1 < EPIPOLAR_RATIO**2 * d2), best

    pa, ba = one_way(Dm)
    pb, bb = one_way(Dm.T)
    return pa, ba, pb, bb


def _midpoints(
    a: Camera, b: Camera, xa: np.ndarray, xb: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint triangulation: the depth in view a of each point, and whether it lies in
    front of both views."""
    ra, rb = a.rays(xa), b.rays(xb)
    ca, cb = a.center, b.center
    w = ca - cb
    aa, bb_, ab = (ra * ra).sum(1), (rb * rb).sum(1), (ra * rb).sum(1)
    den = aa * bb_ - ab**2
    ok = den > 1e-9
    sa = np.where(ok, (ab * (rb @ w) - bb_ * (ra @ w)) / np.where(ok, den, 1), 0)
    sb = np.where(ok, (aa * (rb @ w) - ab * (ra @ w)) / np.where(ok, den, 1), 0)
    X = ca + sa[:, None] * ra
    za = a.to_camera(X)[:, 2]
    zb = b.to_camera(cb + sb[:, None] * rb)[:, 2]
    return za, ok & (sa > 0) & (sb > 0) & (zb > 0)


def triangulate_depths(a: Camera, b: Camera, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """The depth in view a of each midpoint-triangulated point in front of both views
    (others dropped)."""
    za, front = _midpoints(a, b, xa, xb)
    return za[front]


def saturation_depth(baseline: float) -> float:
    """The distance at which a baseline subtends the parallax saturation angle."""
    return baseline / (2 * math.tan(math.radians(PARALLAX_SATURATION_DEG) / 2))


def ray_angles(
    cand: Candidates, cam: Camera, others: list[Camera], depth: float
) -> tuple[np.ndarray, np.ndarray]:
    """For the point at `depth` along each candidate's ray: the sum over the `others` that
    see it of the angle (degrees) at the point between the two camera centres, and how
    many see it."""
    X = cam.center + depth * cam.rays(cand.xy)
    total, count = np.zeros(len(cand)), np.zeros(len(cand))
    for other in others:
        uv, z = other.project(X)
        vis = (
            (z > 0)
            & (uv[:, 0] >= 0)
            & (uv[:, 0] < other.width)
            & (uv[:, 1] >= 0)
            & (uv[:, 1] < other.height)
        )
        u, v = cam.center - X, other.center - X
        cos = (u * v).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        total += np.where(vis, np.degrees(np.arccos(np.clip(cos, -1, 1))), 0)
        count += vis
    return total, count


def parallax(cand: Candidates, cams: list[Camera], i: int, depth: float) -> np.ndarray:
    """p = min(1, theta / 10 deg), theta the mean ray angle over the other views that see
    the point at `depth` along each candidate's ray."""
    total, count = ray_angles(cand, cams[i], [c for j, c in enumerate(cams) if j != i], depth)
    theta = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    return np.minimum(1.0, theta / PARALLAX_SATURATION_DEG)


@dataclass
class Frame:
    """View i and some other views in one coordinate system, and i's working distance there."""

    camera: Camera
    others: list[Camera]
    depth: float


@dataclass
class Geometry:
    """What the signals may know of the views' relative geometry (module docstring)."""

    source: str
    """RIG (the calibration's poses) or IMAGES (estimated from the images)."""
    overlap: list[list[int]]
    nearest: list[set[int]]
    pair_frame: dict[tuple[int, int], tuple[Camera, Camera]] = field(default_factory=dict)
    """(i, j), i < j, overlapping with a translation between them: both cameras in one frame."""
    frames: list[list[Frame]] = field(default_factory=list)
    """Per view, the frames its parallax is judged in."""

    def fundamental(self, i: int, j: int) -> np.ndarray | None:
        """F of views i < j (x_j^T F x_i = 0), or None without a translation between them."""
        pair = self.pair_frame.get((i, j))
        return None if pair is None else fundamental(*pair)

    def parallax(self, i: int, cand: Candidates) -> np.ndarray:
        """The parallax signal of view i's candidates (`parallax`, over every frame of i)."""
        total, count = np.zeros(len(cand)), np.zeros(len(cand))
        for f in self.frames[i]:
            t, c = ray_angles(cand, f.camera, f.others, f.depth)
            total += t
            count += c
        theta = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
        return np.minimum(1.0, theta / PARALLAX_SATURATION_DEG)


def view_geometry(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> Geometry:
    """The rig's geometry when every view is posed, else the geometry of the images."""
    if all(v.posed for v in views):
        return rig_geometry(views, pools, cfg)
    return image_geometry(views, pools, cfg)


def _strongest(pools: list[Candidates], k: int) -> list[np.ndarray]:
    return [strongest_first(c.response)[:k] for c in pools]


def depth_priors(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> list[float]:
    """Each view's working distance from the poses (module docstring)."""
    n = len(views)
    if cfg.depth_prior is not None:
        return [float(cfg.depth_prior)] * n
    cams = [v.camera for v in views]
    strong = _strongest(pools, DEPTH_CANDIDATES)
    found: list[list[np.ndarray]] = [[] for _ in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            if cams[i].R[2] @ cams[j].R[2] <= 0 or not len(strong[i]) or not len(strong[j]):
                continue
            xa, xb = pools[i].xy[strong[i]], pools[j].xy[strong[j]]
            D2 = descriptor_distances(
                pools[i].descriptors[strong[i]], pools[j].descriptors[strong[j]], squared=True
            )
            E = epipolar_distances(fundamental(cams[i], cams[j]), xa, xb)
            pa, ba, pb, bb = epipolar_matches(D2, E)
            mutual = np.flatnonzero(pa & pb[ba] & (bb[ba] == np.arange(len(ba))))
            found[i].append(triangulate_depths(cams[i], cams[j], xa[mutual], xb[ba[mutual]]))
            found[j].append(triangulate_depths(cams[j], cams[i], xb[ba[mutual]], xa[mutual]))
    per_view = [np.concatenate(f) if f else np.zeros(0) for f in found]
    every = np.concatenate(per_view)
    if len(every) >= DEPTH_MIN_POINTS:
        fallback = float(np.median(every))
    else:
        centres = np.array([c.center for c in cams])
        gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.diag([np.inf] * n)
        fallback = saturation_depth(float(np.median(gaps.min(1))))
    return [float(np.median(d)) if len(d) >= DEPTH_MIN_POINTS else fallback for d in per_view]


def overlapping(cams: list[Camera], i: int, j: int, depths: list[float]) -> bool:
    """Whether view j sees the point at view i's working distance on its optical axis, or
    view i sees view j's."""
    for a, b in ((i, j), (j, i)):
        X = cams[a].center + depths[a] * cams[a].R[2]
        uv, z = cams[b].project(X[None])
        if z[0] > 0 and 0 <= uv[0, 0] < cams[b].width and 0 <= uv[0, 1] < cams[b].height:
            return True
    return False


def rig_geometry(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> Geometry:
    """The geometry of the calibration's poses (module docstring)."""
    n = len(views)
    cams = [v.camera for v in views]
    depths = depth_priors(views, pools, cfg)
    overlap = [
        [j for j in range(n) if j != i and overlapping(cams, i, j, depths)] for i in range(n)
    ]
    centres = [c.center for c in cams]
    nearest = [
        set(sorted(o, key=lambda j: np.linalg.norm(centres[j] - centres[i]))[:AMBIGUITY_VIEWS])
        for i, o in enumerate(overlap)
    ]
    pair_frame = {(i, j): (cams[i], cams[j]) for i in range(n) for j in overlap[i] if i < j}
    frames = [
        [Frame(cams[i], [c for j, c in enumerate(cams) if j != i], depths[i])] for i in range(n)
    ]
    return Geometry(RIG, overlap, nearest, pair_frame, frames)


def _pair_camera(cam: Camera, R: np.ndarray, t: np.ndarray) -> Camera:
    return Camera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, R, t)


def _relative_pose(
    cam_a: Camera, xa: np.ndarray, cam_b: Camera, xb: np.ndarray
) -> tuple[Camera, Camera, np.ndarray] | None:
    """COLMAP's relative pose of two views from matched points (xa[k] <-> xb[k]): the two
    cameras in a frame of unit baseline, and the indices of the matches the pose explains
    (module docstring); None without a pose or without a translation."""
    ids = np.arange(len(xa))
    opts = verification_options(FIRST_PASS_MAX_ERROR, RANSAC_SEED, FIRST_PASS_TRIALS)
    tvg = two_view_geometry(cam_a, xa, cam_b, xb, np.c_[ids, ids], opts)
    pose = tvg.cam2_from_cam1
    if pose is None:
        return None
    t = np.asarray(pose.translation, float)
    if not np.all(np.isfinite(t)) or np.linalg.norm(t) < 1e-6:
        return None
    a = _pair_camera(cam_a, np.eye(3), np.zeros(3))
    b = _pair_camera(cam_b, np.asarray(pose.rotation.matrix()), t / np.linalg.norm(t))
    E = np.diagonal(epipolar_distances(fundamental(a, b), xa, xb))
    near = np.flatnonzero(E <= FIRST_PASS_MAX_ERROR)
    return a, b, near[_midpoints(a, b, xa[near], xb[near])[1]]


def _first_pass(pools: list[Candidates], strong: list[np.ndarray], i: int, j: int):
    """The first pass's tentative matches of views i and j: their pixels (xa[k] <-> xb[k])."""
    si, sj = strong[i], strong[j]
    m = tentative_matches(pools[i].descriptors[si], pools[j].descriptors[sj], FIRST_PASS_RATIO)
    return pools[i].xy[si][m[:, 0]], pools[j].xy[sj][m[:, 1]]


@dataclass(frozen=True)
class FocalEstimate:
    """`estimate_focal`'s answer: the focal factor (x max(width, height)) and the pairs of
    views it rests on, or None and why the images do not determine it."""

    factor: float | None
    pairs: int
    explained: tuple[int, int] = (0, 0)
    """First-pass matches the relative poses explain at the best focal factor, and at most
    at FOCAL_OFF times or 1 / FOCAL_OFF times it."""
    why: str = ""


def estimate_focal(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> FocalEstimate:
    """The focal factor of the views whose focal length is guessed, where the images
    determine it (module docstring)."""
    guessed = [i for i, v in enumerate(views) if not v.focal_known]
    strong = _strongest(pools, cfg.first_pass)
    opts = pycolmap.RANSACOptions()
    opts.max_error, opts.random_seed, opts.max_num_trials = (
        FIRST_PASS_MAX_ERROR,
        RANSAC_SEED,
        FIRST_PASS_TRIALS,
    )
    costs, weights, pairs = [], [], []
    for i, j in combinations(guessed, 2):
        xa, xb = _first_pass(pools, strong, i, j)
        fit = pycolmap.estimate_fundamental_matrix(xa, xb, opts) if len(xa) >= 8 else None
        if fit is None or int(np.sum(fit["inlier_mask"])) < MIN_SUPPORT:
            continue
        ka, kb = (_intrinsics(views[v].camera, FOCAL_FACTORS) for v in (i, j))
        sv = np.linalg.svd(kb.transpose(0, 2, 1) @ fit["F"] @ ka, compute_uv=False)
        costs.append((sv[:, 0] - sv[:, 1]) / np.maximum(sv[:, 0] + sv[:, 1], 1e-300))
        weights.append(int(np.sum(fit["inlier_mask"])))
        pairs.append((views[i].camera, xa, views[j].camera, xb))
    if len(costs) < FOCAL_MIN_PAIRS:
        why = (
            f"{len(costs)} pair(s) of images share {MIN_SUPPORT} matches, {FOCAL_MIN_PAIRS} needed"
        )
        return FocalEstimate(None, len(costs), why=why)
    best = int(np.average(costs, axis=0, weights=weights).argmin())
    if best in (0, len(FOCAL_FACTORS) - 1):
        lo, hi = FOCAL_FACTORS[[0, -1]]
        why = (
            f"the best fit lies at the end of the range searched, {lo:.1f} to {hi:.1f} ({CRITICAL})"
        )
        return FocalEstimate(None, len(costs), why=why)
    factor, score = _most_support(pairs, float(FOCAL_FACTORS[best]))
    off = max(_support(pairs, factor * FOCAL_OFF), _support(pairs, factor / FOCAL_OFF))
    if score < FOCAL_PEAK * off:
        why = (
            f"their relative poses explain {score} matches at {factor:.2f} x max(width, "
            f"height) and {off} at {FOCAL_OFF:g} times or 1/{FOCAL_OFF:g} of that ({FOCAL_PEAK:g} "
            f"times as many needed at the estimate; {CRITICAL})"
        )
        return FocalEstimate(None, len(costs), (score, off), why)
    return FocalEstimate(factor, len(costs), (score, off))


def _support(pairs: list, factor: float) -> int:
    """The first-pass matches that the pairs' calibrated relative poses explain at the
    focal factor `factor`."""
    total = 0
    for cam_a, xa, cam_b, xb in pairs:
        pose = _relative_pose(focal_camera(cam_a, factor), xa, focal_camera(cam_b, factor), xb)
        total += 0 if pose is None else len(pose[2])
    return total


def _most_support(pairs: list, factor: float) -> tuple[float, int]:
    """From `factor`, steps of FOCAL_STEPS (then finer) towards the focal factor whose
    calibrated relative poses explain the most first-pass matches over `pairs`; that
    factor and the matches explained."""
    score = _support(pairs, factor)
    for step in FOCAL_STEPS:
        for direction in (step, 1 / step):
            while (trial := _support(pairs, factor * direction)) > score:
                factor, score = factor * direction, trial
    return factor, score


def focal_camera(cam: Camera, factor: float) -> Camera:
    """`cam` with focal length factor x max(width, height)."""
    f = factor * max(cam.width, cam.height)
    return Camera(cam.width, cam.height, f, f, cam.cx, cam.cy, cam.R, cam.t)


def _intrinsics(cam: Camera, factors: np.ndarray) -> np.ndarray:
    """(F, 3, 3): K of `cam` with each focal factor (x max(width, height))."""
    K = np.tile(cam.K, (len(factors), 1, 1))
    K[:, 0, 0] = K[:, 1, 1] = factors * max(cam.width, cam.height)
    return K


def image_geometry(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> Geometry:
    """The geometry estimated from the images and intrinsics alone (module docstring)."""
    n = len(views)
    cams = [v.camera for v in views]
    strong = _strongest(pools, cfg.first_pass)
    support: dict[tuple[int, int], int] = {}
    pair_frame: dict[tuple[int, int], tuple[Camera, Camera]] = {}
    frames: list[list[Frame]] = [[] for _ in range(n)]
    for i, j in combinations(range(n), 2):
        xa, xb = _first_pass(pools, strong, i, j)
        if len(xa) < MIN_SUPPORT:
            continue
        pose = _relative_pose(cams[i], xa, cams[j], xb)
        if pose is None or len(pose[2]) < MIN_SUPPORT:
            continue
        a, b, explained = pose
        support[i, j] = len(explained)
        pair_frame[i, j] = a, b
        for u, cu, cv, xu, xv in ((i, a, b, xa, xb), (j, b, a, xb, xa)):
            d = triangulate_depths(cu, cv, xu[explained], xv[explained])
            depth = float(np.median(d)) if len(d) >= DEPTH_MIN_POINTS else saturation_depth(1.0)
            frames[u].append(Frame(cu, [cv], depth))
    overlap = [
        sorted({b for a, b in support if a == i} | {a for a, b in support if b == i})
        for i in range(n)
    ]
    nearest = [
        set(sorted(o, key=lambda j: (-support[min(i, j), max(i, j)], j))[:AMBIGUITY_VIEWS])
        for i, o in enumerate(overlap)
    ]
    alone = [views[i].name for i in range(n) if not overlap[i]]
    if alone:
        log(
            f"geometry from the images: {', '.join(alone)} share(s) too few verified matches "
            "with every other view to estimate its pose; their parallax and epipolar signals are 0"
        )
    return Geometry(IMAGES, overlap, nearest, pair_frame, frames)
