"""The signals at photo scale: computed without N x N matrices, and equal to the dense
definitions (brute force) on random points and descriptors, ties included."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy.spatial import cKDTree

from bench.camera import look_at
from bench.frontend.features import Candidates, DetectorConfig, descriptor_distances
from bench.frontend.geometry import (
    EPIPOLAR_PX,
    SignalConfig,
    epipolar_distances,
    epipolar_matches,
    fundamental,
)
from bench.frontend.signals import (
    BLOCK_ROWS,
    SAME_POINT_PX,
    compute_signals,
    cross_view_near_duplicates,
    epipolar_pairs,
    epipolar_passes,
    same_view_neighbours,
)
from bench.frontend.views import View

W, H = 640, 480


def _pair(motion: str):
    """Two cameras whose epipoles lie inside the image (forward), at infinity (sideways,
    no depth component), far away (nearly sideways) or anywhere (general)."""
    a = look_at((0.0, -8.0, 1.0), (0.0, 0.0, 1.0), width=W, height=H)
    to = {
        "forward": ((0.1, -6.0, 1.05), (0.1, 2.0, 1.05)),
        "sideways": ((1.0, -8.0, 1.0), (1.0, 0.0, 1.0)),
        "far": ((1.0, -8.0 + 1e-7, 1.0), (1.0, 1e-7, 1.0)),
        "general": ((1.3, -7.0, 1.6), (0.2, 0.3, 0.8)),
    }[motion]
    return a, look_at(*to, width=W, height=H)


def _points(a, b, rng, n=700):
    """Random points of both views, true correspondences (on each other's epipolar lines),
    duplicated points and points at and near the epipoles."""
    X = np.c_[rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(0, 2, n)]
    xa, xb = a.project(X)[0], b.project(X)[0]
    xa = np.r_[xa, rng.uniform(0, W, (n, 2))]
    xb = np.r_[xb, rng.uniform(0, W, (n, 2))]
    F = fundamental(a, b)
    for x, e in ((xa, np.linalg.svd(F)[2][2]), (xb, np.linalg.svd(F)[0][:, 2])):
        if abs(e[2]) > 1e-9 and np.all(np.abs(e[:2] / e[2]) < 1e4):
            x[:3] = e[:2] / e[2] + [[0, 0], [0.5, 0], [0, 2.0]]
    return F, np.r_[xa, xa[:20]], np.r_[xb, xb[:20]]


@pytest.mark.parametrize("motion", ["forward", "sideways", "far", "general"])
def test_epipolar_pairs_are_the_dense_band(motion):
    a, b = _pair(motion)
    F, xa, xb = _points(a, b, np.random.default_rng(0))
    ia, ib = (np.concatenate(x) for x in zip(*epipolar_pairs(F, xa, xb)))
    dense = np.argwhere(epipolar_distances(F, xa, xb) <= EPIPOLAR_PX)
    assert len(dense) > 2 * len(xa)  # the band holds something
    assert sorted(zip(ia, ib)) == sorted(map(tuple, dense))


def _descriptors(rng, n, binary, copies):
    """Random unit (or binary) descriptors, `copies` of them repeated (exact ties)."""
    if binary:
        d = rng.integers(0, 256, (n, 32), dtype=np.uint8)
    else:
        d = rng.normal(size=(n, 128)).astype(np.float32)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[rng.integers(0, n, copies)] = d[rng.integers(0, n, copies)]
    return d


def _candidates(xy, desc):
    n = len(xy)
    return Candidates(xy, np.full(n, 4.0), np.zeros(n), np.ones(n), desc)


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("motion", ["forward", "general"])
def test_epipolar_passes_equal_the_dense_ratio_test(motion, binary):
    a, b = _pair(motion)
    rng = np.random.default_rng(1)
    F, xa, xb = _points(a, b, rng)
    da = _descriptors(rng, len(xa), binary, 200)
    db = _descriptors(rng, len(xb), binary, 200)
    db[: len(xa) // 4] = da[: len(xa) // 4]  # matches, some with tied rivals
    pa, pb = epipolar_passes(F, _candidates(xa, da), _candidates(xb, db))
    D2 = descriptor_distances(da, db, squared=True)
    ra, _, rb, _ = epipolar_matches(D2, epipolar_distances(F, xa, xb))
    assert ra.sum() > 50 and rb.sum() > 50
    assert np.array_equal(pa, ra) and np.array_equal(pb, rb)


@pytest.mark.parametrize("binary", [False, True])
def test_descriptor_neighbours_equal_the_dense_definitions(binary):
    rng = np.random.default_rng(2)
    n = 2 * BLOCK_ROWS + 77  # blocks, and a partial one
    xy = rng.uniform(0, 200, (n, 2))
    xy[1::7] = xy[::7][: len(xy[1::7])] + rng.uniform(-3, 3, (len(xy[1::7]), 2))  # one point
    desc = _descriptors(rng, n, binary, 300)
    desc[1::7] = desc[::7][: len(desc[1::7])]  # the same point twice: never its own rival
    tau2 = (0.2 if binary else 0.3) ** 2 * (4 if binary else 8)  # many near duplicates
    D = descriptor_distances(desc, desc, squared=True)
    pairs = cKDTree(xy).query_pairs(SAME_POINT_PX, output_type="ndarray")
    D[pairs[:, 0], pairs[:, 1]] = D[pairs[:, 1], pairs[:, 0]] = np.inf
    np.fill_diagonal(D, np.inf)
    d1, near, _ = same_view_neighbours(_candidates(xy, desc), tau2)
    np.testing.assert_allclose(d1, D.min(1), rtol=1e-6, atol=1e-6)
    assert np.array_equal(near, (D < tau2).sum(1)) and near.max() > 2
    other = _descriptors(rng, n + 5, binary, 10)
    other[:300] = desc[:300]
    D2 = descriptor_distances(desc, other, squared=True)
    na, nb = cross_view_near_duplicates(desc, other, tau2)
    assert np.array_equal(na, (D2 < tau2).sum(1)) and np.array_equal(nb, (D2 < tau2).sum(0))


def test_signals_of_thousands_of_candidates_hold_no_n_by_n_matrix():
    """Two overlapping views of 6,000 candidates: a dense matrix of them is 144 MB
    (float32), or 288 MB (float64); the signals stay far below that."""
    rng = np.random.default_rng(3)
    cams = [look_at((x, -8.0, 1.0), (0.0, 0.0, 1.0), width=W, height=H) for x in (-0.5, 0.5)]
    n = 6000
    X = np.c_[rng.uniform(-2.5, 2.5, n), rng.uniform(-1.5, 1.5, n), rng.uniform(0, 2, n)]
    desc = _descriptors(rng, n, False, 0)
    views, pools = [], []
    for k, cam in enumerate(cams):
        views.append(View(k, f"v{k}.png", np.zeros((H, W, 3), np.uint8), cam))
        pools.append(_candidates(cam.project(X)[0], desc))
    tracemalloc.start()
    try:
        sigs, _ = compute_signals(views, pools, DetectorConfig(), SignalConfig())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert sigs[0].epipolar.mean() > 0.4  # true matches pass
    assert peak < 60e6, peak / 1e6
