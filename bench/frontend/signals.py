"""The quality signals of every candidate (paper, section 4.1, and two additions), each in
[0, 1] per view.

Computed only from the images, the candidate pools and the calibration. With N candidates
in view i (keypoint x, scale s, response, descriptor d; descriptor distance `dist` is the
L2 distance of unit SIFT descriptors, or the Hamming fraction of binary ones):

* texture t: minimum eigenvalue of the structure tensor of the image gradients summed
  over a box of radius clip(s/2, 2, 32) px around x; t = min-max of log(lambda_min + 1e-6).
* repeatability r (a cheap estimate, read by adaptive-fast and the policies built on it):
  sqrt(iso * c), with iso = lambda_min /
  lambda_max of that structure tensor (1 for a corner, 0 for an edge) and c the min-max of
  log(detector response): a corner-like, high-contrast extremum is re-detected under
  perturbations, an edge-like or faint one is not. Costs no detection.
* repeatability_redetect (the paper's definition, read by `adaptive`; four detections per
  view): the fraction
  of a fixed set of synthetic perturbations of the view (rotation+scale homography,
  perspective tilt, blur+noise, exposure change) under which the detector fires again
  within max(2, s/4) px of x's mapped position, over the perturbations that keep x inside.
* distinctiveness q: d1 / P90(d1) clipped to 1, where d1 is the distance from the
  descriptor to its nearest descriptor in the same view among candidates >= 8 px away.
* ambiguity a: with n0 the number of same-view candidates >= 8 px away within the
  near-duplicate distance tau (0.3 SIFT, 0.2 binary) and n_j the number within tau in view
  j, for the (up to) two views j that the calibration says overlap view i with the camera
  centres nearest to view i's, a_raw = n0 + sum_j max(n_j - 1, 0) (one true match per view
  is expected); a = log(1 + a_raw) / log(1 + max a_raw).
* parallax usefulness p: X = C_i + D_i * ray(x) with view i's depth prior D_i; theta = mean
  over the other views that see X of the angle at X between the two camera centres;
  p = min(1, theta / 10 deg). Near an epipole (e.g. the vanishing point of forward motion)
  theta, and so p, is small.
* epipolar e (beyond the paper; the calibration's poses let a candidate see other views):
  the number of overlapping views j in which the candidate's nearest descriptor among
  view j's candidates within 3 px of its epipolar line passes the ratio test (0.8) against
  the second nearest there, over 2 (a multiview track needs two other views), clipped to 1.

Depth prior D_i (SignalConfig.depth_prior None, the default): the median depth in view i of
the points triangulated from mutual epipolar matches (as for e) between the 150 strongest
candidates of view i and of every view whose optical axis is within 90 degrees; the median
over all views when view i has fewer than 10; without any match, the depth at which the
nearest other camera sees a point at the parallax saturation angle.

Overlap of views i and j: j sees the point at D_i on i's optical axis, or i the point at D_j
on j's.

Without poses (`View.posed` False: a folder of photographs without a model) the signals
that need them are off: parallax and epipolar are 0 for every candidate and ambiguity
counts the same view only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bench.camera import Camera
from bench.frontend.features import Candidates, DetectorConfig, descriptor_distances, detect_points
from bench.frontend.views import View

DUPLICATE_DISTANCE = {"sift": 0.3, "orb": 0.2, "akaze": 0.2}
SAME_POINT_PX = 8.0
PARALLAX_SATURATION_DEG = 10.0
EPIPOLAR_PX = 3.0
EPIPOLAR_RATIO = 0.8
DEPTH_CANDIDATES = 150
DEPTH_MIN_POINTS = 10
AMBIGUITY_VIEWS = 2


@dataclass(frozen=True)
class SignalConfig:
    """Settings of the quality signals."""

    depth_prior: float | None = None
    """Working distance in scene units at which parallax and overlap are judged; None (the
    default) estimates it per view from the calibration and sparse epipolar matches."""


@dataclass
class Signals:
    """The signals of one view's candidates, each (N,) in [0, 1]."""

    texture: np.ndarray
    repeatability: np.ndarray
    repeatability_redetect: np.ndarray
    distinctiveness: np.ndarray
    ambiguity: np.ndarray
    parallax: np.ndarray
    epipolar: np.ndarray


SIGNALS = tuple(f.name for f in fields(Signals))


def _minmax(x: np.ndarray) -> np.ndarray:
    span = x.max() - x.min() if len(x) else 0.0
    return (x - x.min()) / span if span > 0 else np.zeros_like(x)


def structure_tensor(gray: np.ndarray, cand: Candidates) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (lambda_min, lambda_max) of the gradient structure tensor summed over a
    box of radius clip(s/2, 2, 32) px around each candidate."""
    g = gray.astype(np.float32) / 255
    ix, iy = (
        cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8,
        cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8,
    )
    sums = [cv2.integral(m) for m in (ix * ix, iy * iy, ix * iy)]
    h, w = g.shape
    r = np.clip(np.round(cand.size / 2), 2, 32)
    x, y = cand.xy[:, 0] - 0.5, cand.xy[:, 1] - 0.5
    x0, x1 = (
        np.clip(np.round(x - r), 0, w).astype(int),
        np.clip(np.round(x + r) + 1, 0, w).astype(int),
    )
    y0, y1 = (
        np.clip(np.round(y - r), 0, h).astype(int),
        np.clip(np.round(y + r) + 1, 0, h).astype(int),
    )
    area = np.maximum((x1 - x0) * (y1 - y0), 1)
    a, c, b = ((s[y1, x1] - s[y0, x1] - s[y1, x0] + s[y0, x0]) / area for s in sums)
    root = np.sqrt(((a - c) / 2) ** 2 + b**2)
    return np.maximum((a + c) / 2 - root, 0), np.maximum((a + c) / 2 + root, 0)


def texture(lam_min: np.ndarray) -> np.ndarray:
    return _minmax(np.log(lam_min + 1e-6))


def repeatability(lam_min: np.ndarray, lam_max: np.ndarray, cand: Candidates) -> np.ndarray:
    iso = np.divide(lam_min, lam_max, out=np.zeros_like(lam_min), where=lam_max > 0)
    contrast = _minmax(np.log(np.maximum(np.abs(cand.response), 1e-12)))
    return np.sqrt(np.clip(iso, 0, 1) * contrast)


def perturbations(gray: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The fixed synthetic perturbations: (perturbed image, homography from the original)."""
    h, w = gray.shape
    rot = cv2.getRotationMatrix2D((w / 2, h / 2), 6.0, 0.92)
    H_rot = np.vstack([rot, [0, 0, 1]])
    src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    dst = np.float32([[0.04 * w, 0.03 * h], [0.97 * w, 0], [w, h], [0.02 * w, 0.95 * h]])
    H_tilt = cv2.getPerspectiveTransform(src, dst)
    noise = np.random.default_rng(0).normal(0, 4.0, gray.shape)
    blurred = np.clip(cv2.GaussianBlur(gray, (0, 0), 1.2) + noise, 0, 255).astype(np.uint8)
    exposed = np.clip(255 * (0.6 * gray / 255.0) ** 1.25, 0, 255).astype(np.uint8)
    eye = np.eye(3)
    return [
        (cv2.warpPerspective(gray, H_rot, (w, h)), H_rot),
        (cv2.warpPerspective(gray, H_tilt, (w, h)), H_tilt),
        (blurred, eye),
        (exposed, eye),
    ]


def repeatability_redetect(gray: np.ndarray, cand: Candidates, det: DetectorConfig) -> np.ndarray:
    h, w = gray.shape
    hits = np.zeros(len(cand))
    seen = np.zeros(len(cand))
    tol = np.maximum(2.0, cand.size / 4)
    for img, H in perturbations(gray):
        pts = detect_points(img, det)
        p = np.c_[cand.xy - 0.5, np.ones(len(cand))] @ H.T
        mapped = p[:, :2] / p[:, 2:] + 0.5
        inside = (mapped[:, 0] >= 0) & (mapped[:, 0] < w) & (mapped[:, 1] >= 0) & (mapped[:, 1] < h)
        seen += inside
        if len(pts):
            d, _ = cKDTree(pts).query(mapped)
            hits += inside & (d <= tol)
    return np.divide(hits, seen, out=np.zeros_like(hits), where=seen > 0)


def _same_view_distances(cand: Candidates) -> np.ndarray:
    """Same-view squared descriptor distances, inf between candidates closer than 8 px (one
    point)."""
    D = descriptor_distances(cand.descriptors, cand.descriptors, squared=True)
    pairs = cKDTree(cand.xy).query_pairs(SAME_POINT_PX, output_type="ndarray")
    D[pairs[:, 0], pairs[:, 1]] = D[pairs[:, 1], pairs[:, 0]] = np.inf
    np.fill_diagonal(D, np.inf)
    return D


def distinctiveness(D2_same: np.ndarray) -> np.ndarray:
    d1 = np.sqrt(D2_same.min(1)) if D2_same.shape[1] else np.zeros(len(D2_same))
    finite = d1[np.isfinite(d1)]
    ref = np.percentile(finite, 90) if len(finite) else 1.0
    return np.clip(np.where(np.isfinite(d1), d1, ref) / max(ref, 1e-12), 0, 1)


def overlapping(cams: list[Camera], i: int, j: int, depths: list[float]) -> bool:
    """Whether view j sees the point at view i's working distance on its optical axis, or
    view i sees view j's."""
    for a, b in ((i, j), (j, i)):
        X = cams[a].center + depths[a] * cams[a].R[2]
        uv, z = cams[b].project(X[None])
        if z[0] > 0 and 0 <= uv[0, 0] < cams[b].width and 0 <= uv[0, 1] < cams[b].height:
            return True
    return False


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


def triangulate_depths(a: Camera, b: Camera, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Midpoint triangulation; the depth in view a of each point in front of both views
    (others dropped)."""
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
    return za[ok & (sa > 0) & (sb > 0) & (zb > 0)]


def depth_priors(views: list[View], pools: list[Candidates], cfg: SignalConfig) -> list[float]:
    """Each view's working distance (see the module docstring)."""
    n = len(views)
    if cfg.depth_prior is not None:
        return [float(cfg.depth_prior)] * n
    cams = [v.camera for v in views]
    strong = [np.argsort(-c.response, kind="stable")[:DEPTH_CANDIDATES] for c in pools]
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
        baseline = float(np.median(gaps.min(1)))
        fallback = baseline / (2 * math.tan(math.radians(PARALLAX_SATURATION_DEG) / 2))
    return [float(np.median(d)) if len(d) >= DEPTH_MIN_POINTS else fallback for d in per_view]


def parallax(cand: Candidates, cams: list[Camera], i: int, depth: float) -> np.ndarray:
    cam = cams[i]
    X = cam.center + depth * cam.rays(cand.xy)
    total, count = np.zeros(len(cand)), np.zeros(len(cand))
    for j, other in enumerate(cams):
        if j == i:
            continue
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
    theta = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    return np.minimum(1.0, theta / PARALLAX_SATURATION_DEG)


def _log_scaled(raw: np.ndarray) -> np.ndarray:
    top = raw.max() if len(raw) else 0
    return np.log1p(raw) / np.log1p(top) if top > 0 else np.zeros_like(raw)


class _Clock:
    """Seconds spent per signal, summed over views."""

    def __init__(self):
        self.seconds = dict.fromkeys(SIGNALS, 0.0)

    def time(self, name: str, fn, *args):
        t = time.perf_counter()
        out = fn(*args)
        self.seconds[name] += time.perf_counter() - t
        return out


def compute_signals(
    views: list[View],
    pools: list[Candidates],
    det: DetectorConfig,
    cfg: SignalConfig,
    wanted: tuple[str, ...] = SIGNALS,
) -> tuple[list[Signals], dict[str, float]]:
    """Signals of every view, and the seconds spent on each signal (summed over views). The
    two costly signals, repeatability_redetect and epipolar, are computed only when
    `wanted` (else 0 for every candidate): a caller that selects with one policy asks for
    what it reads."""
    n, clock = len(views), _Clock()
    cams = [v.camera for v in views]
    posed = all(v.posed for v in views)
    tau2 = DUPLICATE_DISTANCE[det.detector] ** 2
    values: list[dict[str, np.ndarray]] = [{} for _ in range(n)]
    near_dupes = [np.zeros(len(c)) for c in pools]
    epi_views = [np.zeros(len(c)) for c in pools]
    for i, (view, cand) in enumerate(zip(views, pools)):
        gray = view.gray
        lam = clock.time("texture", structure_tensor, gray, cand)
        values[i]["texture"] = clock.time("texture", texture, lam[0])
        values[i]["repeatability"] = clock.time("repeatability", repeatability, *lam, cand)
        values[i]["repeatability_redetect"] = (
            clock.time("repeatability_redetect", repeatability_redetect, gray, cand, det)
            if "repeatability_redetect" in wanted
            else np.zeros(len(cand))
        )
        D = clock.time("distinctiveness", _same_view_distances, cand)
        values[i]["distinctiveness"] = clock.time("distinctiveness", distinctiveness, D)
        near_dupes[i] += clock.time("ambiguity", np.sum, D < tau2, 1)
    if posed:
        # the depth prior serves parallax and overlap (and so ambiguity); timed with parallax
        depths = clock.time("parallax", depth_priors, views, pools, cfg)
        for i in range(n):
            values[i]["parallax"] = clock.time("parallax", parallax, pools[i], cams, i, depths[i])
        overlap = [
            [j for j in range(n) if j != i and overlapping(cams, i, j, depths)] for i in range(n)
        ]
        centres = [c.center for c in cams]
        nearest = [
            set(sorted(o, key=lambda j: np.linalg.norm(centres[j] - centres[i]))[:AMBIGUITY_VIEWS])
            for i, o in enumerate(overlap)
        ]
        for i in range(n):  # one descriptor distance matrix per overlapping pair
            for j in overlap[i]:
                shared = (j in nearest[i]) + (i in nearest[j])
                epi = "epipolar" in wanted
                if j < i or not (len(pools[i]) and len(pools[j])) or not (shared or epi):
                    continue
                t0 = time.perf_counter()
                D2 = descriptor_distances(pools[i].descriptors, pools[j].descriptors, squared=True)
                t1 = time.perf_counter()
                if j in nearest[i]:
                    near_dupes[i] += np.maximum((D2 < tau2).sum(1) - 1, 0)
                if i in nearest[j]:
                    near_dupes[j] += np.maximum((D2 < tau2).sum(0) - 1, 0)
                t2 = time.perf_counter()
                # each signal is charged the whole distance matrix it reads: its cost alone
                clock.seconds["ambiguity"] += ((t1 - t0) if shared else 0.0) + (t2 - t1)
                if epi:
                    F = fundamental(cams[i], cams[j])
                    xy_i, xy_j = pools[i].xy, pools[j].xy
                    pa, _, pb, _ = epipolar_matches(D2, epipolar_distances(F, xy_i, xy_j))
                    clock.seconds["epipolar"] += (t1 - t0) + time.perf_counter() - t2
                    epi_views[i] += pa
                    epi_views[j] += pb
    for i in range(n):
        values[i]["ambiguity"] = _log_scaled(near_dupes[i])
        if posed:
            values[i]["epipolar"] = np.minimum(1.0, epi_views[i] / 2)
        else:
            values[i]["parallax"] = values[i]["epipolar"] = np.zeros(len(pools[i]))
    return [Signals(**v) for v in values], clock.seconds
