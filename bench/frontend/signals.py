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

None of them holds an N x N matrix of a photograph's thousands of candidates, and each
equals its definition above (tests/test_signals_scale.py): distinctiveness and ambiguity
read the descriptor distances in blocks of BLOCK_ROWS rows; epipolar reads only the pairs
within the band around each epipolar line (`epipolar_pairs`) and their descriptor distances.

Every signal is defined on every pool. On a learned pool (ALIKED, DISK, XFeat:
`bench.frontend.learned`) the response is the detection score, the scale s a nominal size
(neither detector has one), re-detection runs the same network (on the perturbed grey
image, as three equal channels), and tau is set per pool (`Pool.duplicate_distance`).

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
    EPIPOLAR_PX,
    EPIPOLAR_RATIO,
    SignalConfig,
    view_geometry,
)
from bench.frontend.pools import POOLS
from bench.frontend.views import View

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


BLOCK_ROWS = 512
"""Rows of a descriptor distance block: the signals read the distances of N candidates to
thousands of others block by block (16 MB at 8192 columns), never as an N x N matrix."""


def _distance_blocks(a: np.ndarray, b: np.ndarray):
    """(start, squared descriptor distances of a[start:start + BLOCK_ROWS] to every b), block
    by block."""
    for s in range(0, len(a), BLOCK_ROWS):
        yield s, descriptor_distances(a[s : s + BLOCK_ROWS], b, squared=True)


def same_view_neighbours(cand: Candidates, tau2: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Per candidate, among the same view's candidates more than 8 px away (one point): the
    squared descriptor distance to the nearest (inf without one) and the number closer
    than tau2 (squared); and the seconds of the counting alone. Each distance is computed
    once (the upper triangle, block by block) and read by both of its candidates."""
    n = len(cand)
    pairs = cKDTree(cand.xy).query_pairs(SAME_POINT_PX, output_type="ndarray")
    rows = np.r_[pairs[:, 0], pairs[:, 1], np.arange(n)]
    cols = np.r_[pairs[:, 1], pairs[:, 0], np.arange(n)]
    order = np.argsort(rows, kind="stable")
    rows, cols = rows[order], cols[order]
    d1, near, counting = np.full(n, np.inf, np.float32), np.zeros(n), 0.0
    desc = cand.descriptors
    for s in range(0, n, BLOCK_ROWS):
        e = min(s + BLOCK_ROWS, n)
        D = descriptor_distances(desc[s:e], desc[s:], squared=True)  # rows s:e, columns s:
        lo, hi = np.searchsorted(rows, [s, e])
        r, c = rows[lo:hi], cols[lo:hi]
        D[r[c >= s] - s, c[c >= s] - s] = np.inf
        d1[s:e] = np.minimum(d1[s:e], D.min(1))
        d1[e:] = np.minimum(d1[e:], D[:, e - s :].min(0, initial=np.inf))
        t = time.perf_counter()
        close = D < tau2
        near[s:e] += close.sum(1)
        near[e:] += close[:, e - s :].sum(0)
        counting += time.perf_counter() - t
    return d1, near, counting


def cross_view_near_duplicates(
    a: np.ndarray, b: np.ndarray, tau2: float
) -> tuple[np.ndarray, np.ndarray]:
    """How many of b's descriptors lie closer than tau2 (squared) to each of a's, and of a's
    to each of b's."""
    na, nb = np.zeros(len(a)), np.zeros(len(b))
    for s, D in _distance_blocks(a, b):
        close = D < tau2
        na[s : s + len(D)] = close.sum(1)
        nb += close.sum(0)
    return na, nb


def distinctiveness(d1_squared: np.ndarray) -> np.ndarray:
    d1 = np.sqrt(d1_squared)
    finite = d1[np.isfinite(d1)]
    ref = np.percentile(finite, 90) if len(finite) else 1.0
    return np.clip(np.where(np.isfinite(d1), d1, ref) / max(ref, 1e-12), 0, 1)


EPIPOLAR_RING = 1.25
"""Radius ratio of the rings around the epipole in which `epipolar_pairs` sorts a view's
candidates by angle: a line's window in a ring holds at most this many times its band."""
LINE_CHUNK, PAIR_CHUNK = 1024, 1 << 13
"""Epipolar lines, and descriptor pairs, handled at a time: they bound the memory of the
band's pairs whatever their number."""


def _expand(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray, members: np.ndarray):
    """The pairs (rows[k], members[p % len(members)]) for p in [lo[k], hi[k])."""
    count = np.maximum(hi - lo, 0)
    pos = np.arange(count.sum()) + np.repeat(lo - (np.cumsum(count) - count), count)
    return np.repeat(rows, count), members[pos % max(len(members), 1)]


def _band(lines: np.ndarray, xb: np.ndarray, e: np.ndarray, px: float):
    """Index pairs (k, m) that hold every point xb[m] within px of lines[k] (homogeneous),
    every line through the point e (homogeneous), and some more: the points are sorted by
    angle around e in rings of radius ratio EPIPOLAR_RING, and each line takes, per ring,
    the window of angles its band can reach there; with e at infinity or so far that the
    lines are parallel to within a pixel over the points, by offset across the lines."""
    norm = np.hypot(lines[:, 0], lines[:, 1])
    good = np.isfinite(norm) & (norm > 1e-12)
    bad, every = np.flatnonzero(~good), np.arange(len(xb))
    out = [_expand(bad, np.zeros_like(bad), np.full_like(bad, len(xb)), every)]
    k = np.flatnonzero(good)
    nl, cl = lines[k, :2] / norm[k, None], lines[k, 2] / norm[k]
    tol = px + 1e-3  # beyond rounding
    c0 = xb.mean(0)
    r0 = np.hypot(*(xb - c0).T).max()
    far = e[:2] - e[2] * c0
    if abs(e[2]) * max(r0**2, 1.0) < np.hypot(*far):  # parallel to within r0^2 / |e - c0| px
        across = np.array([-far[1], far[0]]) / np.hypot(*far)
        sign = np.where(nl @ across < 0, -1.0, 1.0)
        nl, cl = nl * sign[:, None], cl * sign
        offset = cl + nl @ c0
        reach = tol + np.hypot(*(nl - across).T) * r0  # |(nl - across).(x - c0)| <= this - tol
        s = (xb - c0) @ across
        order = np.argsort(s, kind="stable")
        lo = np.searchsorted(s[order], -offset - reach, "left")
        hi = np.searchsorted(s[order], -offset + reach, "right")
        out.append(_expand(k, lo, hi, order))
    else:
        ep = e[:2] / e[2]
        v = xb - ep
        r, th = np.hypot(v[:, 0], v[:, 1]), np.mod(np.arctan2(v[:, 1], v[:, 0]), np.pi)
        th_l = np.mod(np.arctan2(-nl[:, 0], nl[:, 1]), np.pi)
        th[th >= np.pi], th_l[th_l >= np.pi] = 0.0, 0.0
        off = np.abs(nl @ ep + cl)  # the line's distance from e: d(x, line) >= r |sin| - off
        ring = np.floor(np.log(np.maximum(r / px, 1)) / np.log(EPIPOLAR_RING)).astype(int)
        for g in np.unique(ring):
            members = np.flatnonzero(ring == g)
            members = members[np.argsort(th[members], kind="stable")]
            n, s = len(members), th[members]
            sin_w = (tol + off) / (px * EPIPOLAR_RING**g) if g else np.ones(len(k))
            w = np.arcsin(np.minimum(sin_w, 1))
            lo_v = th_l - w
            lo_v[lo_v < 0] += np.pi
            ext = np.r_[s, s + np.pi]
            lo = np.searchsorted(ext, lo_v, "left")
            hi = np.minimum(np.searchsorted(ext, lo_v + 2 * w, "right"), lo + n)
            full = sin_w >= 1
            lo[full], hi[full] = 0, n
            out.append(_expand(k, lo, hi, members))
    return tuple(np.concatenate(x).astype(np.int64) for x in zip(*out))


def epipolar_pairs(F: np.ndarray, xa: np.ndarray, xb: np.ndarray, px: float = EPIPOLAR_PX):
    """The index pairs (ia, ib) whose epipolar distance (`epipolar_distances`: the larger of
    the two point-to-line distances) is at most px, `LINE_CHUNK` points of a at a time,
    without the Na x Nb matrix: the candidates of the band around each line in b
    (`_band`), then the distance of each."""
    ha, hb = np.c_[xa, np.ones(len(xa))], np.c_[xb, np.ones(len(xb))]
    la, lb = ha @ F.T, hb @ F
    inv_a = 1 / np.maximum(np.hypot(la[:, 0], la[:, 1]), 1e-12)
    inv_b = 1 / np.maximum(np.hypot(lb[:, 0], lb[:, 1]), 1e-12)
    e = np.linalg.svd(F)[0][:, 2]
    for s in range(0, len(xa), LINE_CHUNK):
        ia, ib = _band(la[s : s + LINE_CHUNK], xb, e, px)
        ia += s
        num = np.abs(np.einsum("ij,ij->i", la[ia], hb[ib]).astype(np.float32))
        keep = num * np.maximum(inv_a[ia], inv_b[ib]).astype(np.float32) <= px
        yield ia[keep], ib[keep]


def pair_distances(a: np.ndarray, b: np.ndarray, ia: np.ndarray, ib: np.ndarray) -> np.ndarray:
    """Squared descriptor distances of the pairs (a[ia[k]], b[ib[k]]), as
    `descriptor_distances` computes them (float32)."""
    out = np.empty(len(ia), np.float32)
    if a.dtype == np.uint8:
        for s in range(0, len(ia), PAIR_CHUNK):
            c = slice(s, s + PAIR_CHUNK)
            bits = np.bitwise_count(a[ia[c]] ^ b[ib[c]]).sum(1).astype(np.float32)
            out[c] = (bits / (8 * a.shape[1])) ** 2
        return out
    na, nb = ((x.astype(np.float32) ** 2).sum(1) for x in (a, b))
    unit = np.allclose(na, 1, atol=1e-4) and np.allclose(nb, 1, atol=1e-4)
    for s in range(0, len(ia), PAIR_CHUNK):
        c = slice(s, s + PAIR_CHUNK)
        d2 = np.einsum("ij,ij->i", a[ia[c]], b[ib[c]], dtype=np.float32) * np.float32(-2)
        if unit:
            d2 += 2
        else:
            d2 += na[ia[c]]
            d2 += nb[ib[c]]
        out[c] = np.maximum(d2, 0)
    return out


def _keep_two(best: np.ndarray, index: np.ndarray, d2: np.ndarray) -> None:
    """Fold the distances d2 of pairs of the candidates `index` into best, (2, N): each
    candidate's two smallest so far."""
    # sorted by (index, d2) as one integer: a non-negative float32's bits order as its value
    # (+ 0 turns -0 into 0); 9 times faster than np.lexsort((d2, index))
    key = np.sort((index.astype(np.int64) << 32) | (d2 + np.float32(0)).view(np.uint32))
    index, d2 = key >> 32, (key & 0xFFFFFFFF).astype(np.uint32).view(np.float32)
    first = np.flatnonzero(np.r_[True, index[1:] != index[:-1]]) if len(index) else index
    nxt = np.minimum(first + 1, len(index) - 1)
    second = np.where((first + 1 < len(index)) & (index[nxt] == index[first]), d2[nxt], np.inf)
    at = index[first]
    b1, b2, c1 = best[0, at], best[1, at], d2[first]
    best[0, at] = np.minimum(b1, c1)
    best[1, at] = np.minimum(np.maximum(b1, c1), np.minimum(b2, second))


def epipolar_passes(F: np.ndarray, a: Candidates, b: Candidates) -> tuple[np.ndarray, np.ndarray]:
    """Whether each candidate of a (of b) has a ratio-passing nearest descriptor among b's
    (a's) candidates within EPIPOLAR_PX of its epipolar line: `epipolar_matches` on the
    pairs of `epipolar_pairs` alone, which are all it reads."""
    best = [np.full((2, len(c)), np.inf, np.float32) for c in (a, b)]
    for ia, ib in epipolar_pairs(F, a.xy, b.xy):
        d2 = pair_distances(a.descriptors, b.descriptors, ia, ib)
        _keep_two(best[0], ia, d2)
        _keep_two(best[1], ib, d2)
    return tuple(np.isfinite(d1) & (d1 < EPIPOLAR_RATIO**2 * d2) for d1, d2 in best)


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
    step=None,
) -> tuple[list[Signals], dict[str, float]]:
    """Signals of every view, and the seconds spent on each signal (summed over views) and
    on the views' geometry (`geometry`: from the poses when every view is posed, else from
    the images; `bench.frontend.geometry`). The two costly signals, repeatability_redetect
    and epipolar, are computed only when `wanted` (else 0 for every candidate): a caller
    that selects with one policy asks for what it reads. `step()`, if given, is called as
    each view's own signals are done (progress)."""
    n, clock = len(views), _Clock()
    tau2 = POOLS[det.detector].duplicate_distance ** 2
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
        t = time.perf_counter()
        d1, near, counting = same_view_neighbours(cand, tau2)
        values[i]["distinctiveness"] = distinctiveness(d1)
        clock.seconds["distinctiveness"] += time.perf_counter() - t - counting
        clock.seconds["ambiguity"] += counting
        near_dupes[i] += near
        if step is not None:
            step()
    geo = clock.time("geometry", view_geometry, views, pools, cfg)
    for i in range(n):
        values[i]["parallax"] = clock.time("parallax", geo.parallax, i, pools[i])
    for i in range(n):
        for j in geo.overlap[i]:
            if j < i or not (len(pools[i]) and len(pools[j])):
                continue
            if j in geo.nearest[i] or i in geo.nearest[j]:
                di, dj = clock.time(
                    "ambiguity",
                    cross_view_near_duplicates,
                    pools[i].descriptors,
                    pools[j].descriptors,
                    tau2,
                )
                if j in geo.nearest[i]:
                    near_dupes[i] += np.maximum(di - 1, 0)
                if i in geo.nearest[j]:
                    near_dupes[j] += np.maximum(dj - 1, 0)
            F = geo.fundamental(i, j) if "epipolar" in wanted else None
            if F is not None:
                pa, pb = clock.time("epipolar", epipolar_passes, F, pools[i], pools[j])
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
