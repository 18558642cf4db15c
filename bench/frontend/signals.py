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
  j, for the (up to) two nearest views j that overlap view i, a_raw = n0 + sum_j
  max(n_j - 1, 0) (one true match per view is expected); a = log(1 + a_raw) /
  log(1 + max a_raw).
* parallax usefulness p: X = C_i + D * ray(x) at view i's working distance D; theta = mean
  over the other views that see X of the angle at X between the two camera centres;
  p = min(1, theta / 10 deg). Near an epipole (e.g. the vanishing point of forward motion)
  theta, and so p, is small.
* epipolar e (beyond the paper): the number of overlapping views j in which the
  candidate's nearest descriptor among view j's candidates within 3 px of its epipolar
  line passes the ratio test (0.8) against the second nearest there, over 2 (a multiview
  track needs two other views), clipped to 1.

Overlap, nearest views, working distances, epipolar lines and the cameras that parallax
looks at come from the views' geometry (`bench.frontend.geometry`): the rig's poses when
the views carry them, else the geometry estimated from the images alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bench.frontend.features import Candidates, DetectorConfig, descriptor_distances, detect_points
from bench.frontend.geometry import (
    SignalConfig,
    epipolar_distances,
    epipolar_matches,
    view_geometry,
)
from bench.frontend.views import View

DUPLICATE_DISTANCE = {"sift": 0.3, "orb": 0.2, "akaze": 0.2}
SAME_POINT_PX = 8.0


@dataclass
class Signals:
    """The signals of one view's candidates, each (N,) float64 in [0, 1], indexed like the
    candidates; higher is better except `ambiguity` (definitions: the module docstring)."""

    texture: np.ndarray
    """Gradient strength around the keypoint (structure tensor's smaller eigenvalue)."""
    repeatability: np.ndarray
    """Cheap estimate of being detected again (corner-ness x response)."""
    repeatability_redetect: np.ndarray
    """Fraction of four perturbed re-detections that find it again."""
    distinctiveness: np.ndarray
    """Descriptor distance to its nearest neighbour in the same view."""
    ambiguity: np.ndarray
    """Near-duplicate descriptors in this and the nearest views (higher: worse)."""
    parallax: np.ndarray
    """Triangulation angle other views give it, / 10 degrees, clipped to 1."""
    epipolar: np.ndarray
    """Overlapping views with a ratio-passing match on its epipolar line, / 2."""


SIGNALS = tuple(f.name for f in fields(Signals))
GEOMETRIC = ("ambiguity", "parallax", "epipolar")
"""The signals that read the views' geometry (`bench.frontend.geometry`)."""
TIMED = ("geometry", *SIGNALS)
"""What the front end's clock measures besides detection."""


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


def _log_scaled(raw: np.ndarray) -> np.ndarray:
    top = raw.max() if len(raw) else 0
    return np.log1p(raw) / np.log1p(top) if top > 0 else np.zeros_like(raw)


class _Clock:
    """Seconds spent per signal and on the geometry, summed over views."""

    def __init__(self):
        self.seconds = dict.fromkeys(TIMED, 0.0)

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
    """Signals of every view, and the seconds spent on each signal (summed over views) and
    on the views' geometry (`geometry`: from the poses when every view is posed, else from
    the images; `bench.frontend.geometry`). The two costly signals, repeatability_redetect
    and epipolar, are computed only when `wanted` (else 0 for every candidate): a caller
    that selects with one policy asks for what it reads."""
    n, clock = len(views), _Clock()
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
    geo = clock.time("geometry", view_geometry, views, pools, cfg)
    for i in range(n):
        values[i]["parallax"] = clock.time("parallax", geo.parallax, i, pools[i])
    for i in range(n):  # one descriptor distance matrix per overlapping pair
        for j in geo.overlap[i]:
            shared = (j in geo.nearest[i]) + (i in geo.nearest[j])
            F = geo.fundamental(i, j) if "epipolar" in wanted and j > i else None
            if j < i or not (len(pools[i]) and len(pools[j])) or not (shared or F is not None):
                continue
            t0 = time.perf_counter()
            D2 = descriptor_distances(pools[i].descriptors, pools[j].descriptors, squared=True)
            t1 = time.perf_counter()
            if j in geo.nearest[i]:
                near_dupes[i] += np.maximum((D2 < tau2).sum(1) - 1, 0)
            if i in geo.nearest[j]:
                near_dupes[j] += np.maximum((D2 < tau2).sum(0) - 1, 0)
            t2 = time.perf_counter()
            # each signal is charged the whole distance matrix it reads: its cost alone
            clock.seconds["ambiguity"] += ((t1 - t0) if shared else 0.0) + (t2 - t1)
            if F is not None:
                xy_i, xy_j = pools[i].xy, pools[j].xy
                pa, _, pb, _ = epipolar_matches(D2, epipolar_distances(F, xy_i, xy_j))
                clock.seconds["epipolar"] += (t1 - t0) + time.perf_counter() - t2
                epi_views[i] += pa
                epi_views[j] += pb
    for i in range(n):
        values[i]["ambiguity"] = _log_scaled(near_dupes[i])
        values[i]["epipolar"] = np.minimum(1.0, epi_views[i] / 2)
    return [Signals(**v) for v in values], clock.seconds


def seconds_of(seconds: dict[str, float], used: tuple[str, ...]) -> float:
    """The front-end seconds a policy reading the signals `used` costs beyond detection:
    those signals, and the views' geometry when it reads a signal that needs it."""
    return sum(seconds[s] for s in used) + (
        seconds["geometry"] if set(used) & set(GEOMETRIC) else 0.0
    )
