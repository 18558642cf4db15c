"""The five quality signals of every candidate (paper, section 4.1), each in [0, 1] per view.

Computed only from the images, the candidate pools and the calibration. With N candidates
in view i (keypoint x, scale s, descriptor d; descriptor distance `dist` is the L2 distance
of unit SIFT descriptors, or the Hamming fraction of binary ones):

* texture t: minimum eigenvalue of the structure tensor of the image gradients summed
  over a box of radius clip(s/2, 2, 32) px around x; t = min-max of log(lambda_min + 1e-6).
* repeatability r: the fraction of a fixed set of synthetic perturbations of the view
  (rotation+scale homography, perspective tilt, blur+noise, exposure change) under which
  the detector fires again within max(2, s/4) px of x's mapped position, over the
  perturbations that keep x inside the image.
* distinctiveness q: d1 / P90(d1) clipped to 1, where d1 is the distance from the
  descriptor to its nearest descriptor in the same view among candidates >= 8 px away.
* ambiguity a: with n0 the number of same-view candidates >= 8 px away within the
  near-duplicate distance tau (0.3 SIFT, 0.2 binary) and n_j the number within tau in an
  adjacent view j that the calibration says overlaps, a_raw = n0 + sum_j max(n_j - 1, 0)
  (one true match per neighbour is expected); a = log(1 + a_raw) / log(1 + max a_raw).
* parallax usefulness p: X = C_i + D * ray(x) with the depth prior D (the rig's nominal
  working distance; no ground truth); theta = mean over the other views that see X of the
  angle at X between the two camera centres; p = min(1, theta / 10 deg). Near an epipole
  (e.g. the vanishing point of forward motion) theta, and so p, is small.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bench.camera import Camera
from bench.frontend.features import Candidates, DetectorConfig, descriptor_distances, detect_points
from bench.frontend.views import View

SIGNALS = ("texture", "repeatability", "distinctiveness", "ambiguity", "parallax")
DUPLICATE_DISTANCE = {"sift": 0.3, "orb": 0.2, "akaze": 0.2}
SAME_POINT_PX = 8.0
PARALLAX_SATURATION_DEG = 10.0


@dataclass(frozen=True)
class SignalConfig:
    """Settings of the quality signals."""

    depth_prior: float = 7.0
    """Nominal working distance of the rig in scene units (the scenes are authored with a
    median camera-to-surface distance of 5 to 10): the depth at which parallax is judged."""


@dataclass
class Signals:
    """The five signals of one view's candidates, each (N,) in [0, 1]."""

    texture: np.ndarray
    repeatability: np.ndarray
    distinctiveness: np.ndarray
    ambiguity: np.ndarray
    parallax: np.ndarray


def _minmax(x: np.ndarray) -> np.ndarray:
    span = x.max() - x.min() if len(x) else 0.0
    return (x - x.min()) / span if span > 0 else np.zeros_like(x)


def texture(gray: np.ndarray, cand: Candidates) -> np.ndarray:
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
    lam_min = (a + c) / 2 - np.sqrt(((a - c) / 2) ** 2 + b**2)
    return _minmax(np.log(np.maximum(lam_min, 0) + 1e-6))


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


def repeatability(gray: np.ndarray, cand: Candidates, det: DetectorConfig) -> np.ndarray:
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
    """Same-view descriptor distances, inf between candidates closer than 8 px (one point)."""
    D = descriptor_distances(cand.descriptors, cand.descriptors)
    pairs = cKDTree(cand.xy).query_pairs(SAME_POINT_PX, output_type="ndarray")
    D[pairs[:, 0], pairs[:, 1]] = D[pairs[:, 1], pairs[:, 0]] = np.inf
    np.fill_diagonal(D, np.inf)
    return D


def distinctiveness(D_same: np.ndarray) -> np.ndarray:
    d1 = D_same.min(1) if D_same.shape[1] else np.zeros(len(D_same))
    finite = d1[np.isfinite(d1)]
    ref = np.percentile(finite, 90) if len(finite) else 1.0
    return np.clip(np.where(np.isfinite(d1), d1, ref) / max(ref, 1e-12), 0, 1)


def overlapping(cams: list[Camera], i: int, j: int, depth: float) -> bool:
    """Whether view j sees the point at the working distance on view i's optical axis, or
    view i sees view j's."""
    for a, b in ((i, j), (j, i)):
        X = cams[a].center + depth * cams[a].R[2]
        uv, z = cams[b].project(X[None])
        if z[0] > 0 and 0 <= uv[0, 0] < cams[b].width and 0 <= uv[0, 1] < cams[b].height:
            return True
    return False


def ambiguity(
    D_same: np.ndarray, pools: list[Candidates], i: int, cams, det: str, depth: float
) -> np.ndarray:
    tau = DUPLICATE_DISTANCE[det]
    raw = (D_same < tau).sum(1).astype(float)
    for j in (i - 1, i + 1):
        if 0 <= j < len(pools) and len(pools[j]) and overlapping(cams, i, j, depth):
            n = (descriptor_distances(pools[i].descriptors, pools[j].descriptors) < tau).sum(1)
            raw += np.maximum(n - 1, 0)
    top = raw.max() if len(raw) else 0
    return np.log1p(raw) / np.log1p(top) if top > 0 else np.zeros_like(raw)


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


def compute_signals(
    views: list[View], pools: list[Candidates], det: DetectorConfig, cfg: SignalConfig
) -> tuple[list[Signals], dict[str, float]]:
    """Signals of every view, and the seconds spent on each signal (summed over views)."""
    cams = [v.camera for v in views]
    seconds = dict.fromkeys(SIGNALS, 0.0)
    out = []
    for i, (view, cand) in enumerate(zip(views, pools)):
        gray = view.gray
        t = time.perf_counter()
        values = {"texture": texture(gray, cand)}
        seconds["texture"] += time.perf_counter() - t
        t = time.perf_counter()
        values["repeatability"] = repeatability(gray, cand, det)
        seconds["repeatability"] += time.perf_counter() - t
        t = time.perf_counter()
        D = _same_view_distances(cand)
        values["distinctiveness"] = distinctiveness(D)
        seconds["distinctiveness"] += time.perf_counter() - t
        t = time.perf_counter()
        values["ambiguity"] = ambiguity(D, pools, i, cams, det.detector, cfg.depth_prior)
        seconds["ambiguity"] += time.perf_counter() - t
        t = time.perf_counter()
        values["parallax"] = parallax(cand, cams, i, cfg.depth_prior)
        seconds["parallax"] += time.perf_counter() - t
        out.append(Signals(**values))
    return out, seconds
