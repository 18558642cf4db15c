"""The COLMAP back end and the metrics, on hand-made cases with known answers."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pycolmap
import pytest
from scipy.spatial import cKDTree

from bench.backend import (
    BackendConfig,
    PairMatches,
    expected_ransac_iterations,
    tentative_matches,
    triangulate,
    verify,
)
from bench.camera import look_at
from bench.evaluate import (
    SceneTruth,
    completeness_pct,
    coverage_pct,
    point_error,
    rmse,
    runtime_proxy,
)
from bench.features import Candidates
from bench.groundtruth import GroundTruth

# --- metrics on five hand-made points -------------------------------------------------

TRUE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 1.0]])


def test_point_error_rmse_median_and_completeness_on_five_points():
    surface = cKDTree(TRUE)
    X = TRUE.copy()
    X[4, 2] += 0.3  # one point 0.3 units off its surface
    e = point_error(X, surface)
    np.testing.assert_allclose(e, [0, 0, 0, 0, 0.3], atol=1e-12)
    assert rmse(e) == pytest.approx(math.sqrt(0.09 / 5))
    assert np.median(e) == 0
    assert completeness_pct(e, 5, 0.10) == pytest.approx(80.0)
    assert completeness_pct(e, 5, 0.20) == pytest.approx(80.0)
    assert completeness_pct(e, 8, 0.50) == pytest.approx(62.5)  # 5 of 8 reconstructable
    X[4, 2] = 1.15
    assert completeness_pct(point_error(X, surface), 5, 0.20) == pytest.approx(100.0)
    assert completeness_pct(point_error(X, surface), 5, 0.02) == pytest.approx(80.0)
    assert math.isnan(rmse(np.zeros(0))) and math.isnan(completeness_pct(e, 0, 0.1))


def test_coverage_of_a_known_layout():
    three_cells = np.array(
        [[1.0, 1.0], [2.0, 2.0], [100.0, 1.0], [630.0, 470.0]]
    )  # 3 cells of 16x12
    every_cell = np.array([[(c + 0.5) * 40, (r + 0.5) * 40] for r in range(12) for c in range(16)])
    assert coverage_pct([three_cells, every_cell], 640, 480) == pytest.approx(
        100 * (3 / 192 + 1) / 2
    )


def test_runtime_proxy_parts():
    r = runtime_proxy([1000, 1000], 5, [10, 20, 30], tentative=[100, 0], verified=[50, 0])
    assert r["runtime_scoring"] == pytest.approx(10.0)  # 2000 candidates x 5 signals / 1000
    assert r["runtime_matching"] == pytest.approx((200 + 300 + 600) / 1000)
    assert r["runtime_robust"] == pytest.approx(100 * expected_ransac_iterations(0.5) / 1000)
    assert r["runtime_proxy"] == pytest.approx(
        r["runtime_scoring"] + r["runtime_matching"] + r["runtime_robust"]
    )


def test_expected_ransac_iterations():
    assert expected_ransac_iterations(0.5) == pytest.approx(math.log(0.001) / math.log(1 - 0.5**5))
    assert expected_ransac_iterations(1.0) == 100.0 and expected_ransac_iterations(0.0) == 10000.0


# --- synthetic two-view geometry ----------------------------------------------------------


def _rig():
    cams = [
        look_at((x, -8.0, 1.0), (0.0, 0.0, 1.0), width=640, height=480)
        for x in (-1.5, -0.5, 0.5, 1.5)
    ]
    rng = np.random.default_rng(3)
    X = np.c_[rng.uniform(-2.5, 2.5, 150), rng.uniform(-1.5, 1.5, 150), rng.uniform(0, 2, 150)]
    return cams, X


def test_verification_removes_planted_outliers():
    cams, X = _rig()
    xa, xb = cams[0].project(X)[0], cams[2].project(X)[0]
    rng = np.random.default_rng(0)
    planted = np.c_[rng.uniform(0, 640, (40, 1)), rng.uniform(0, 480, (40, 1))]
    xb = np.concatenate([xb, planted])
    xa = np.concatenate([xa, rng.uniform(0, 480, (40, 2))])
    matches = np.c_[np.arange(190), np.arange(190)]
    inliers, config = verify(cams[0], xa, cams[2], xb, matches, BackendConfig())
    kept = set(inliers[:, 0].tolist())
    assert config == "CALIBRATED"
    assert len(kept & set(range(150))) >= 145
    assert len(kept & set(range(150, 190))) <= 4


def _triangulate_exact(cams, X, noise_px, tmp_path):
    rng = np.random.default_rng(1)
    xy = [c.project(X)[0] + rng.normal(0, noise_px, (len(X), 2)) for c in cams]
    ids = np.arange(len(X))
    pairs = [
        PairMatches(i, j, np.c_[ids, ids], np.c_[ids, ids], "CALIBRATED")
        for i in range(4)
        for j in range(i + 1, 4)
    ]
    names = [f"view_{k:02d}.png" for k in range(4)]
    for n in names:
        cv2.imwrite(str(tmp_path / n), np.zeros((480, 640, 3), np.uint8))
    model = triangulate(tmp_path, cams, names, xy, pairs, BackendConfig())
    got = {}
    for p in model.points3D.values():
        obs = {el.image_id: el.point2D_idx for el in p.track.elements}
        got[obs[min(obs)]] = p.xyz
    return got


def test_triangulation_with_known_poses_recovers_exact_points(tmp_path):
    cams, X = _rig()
    got = _triangulate_exact(cams, X, 0.0, tmp_path)
    assert len(got) == len(X)
    err = np.array([np.linalg.norm(got[k] - X[k]) for k in got])
    # COLMAP's database stores keypoints as float32 (~4e-5 px at x = 640), which alone
    # moves a point at depth 8 by up to ~1e-6 units: that is the floor of "exact" here.
    assert np.median(err) < 1e-6 and err.max() < 5e-6


def test_triangulation_error_under_half_pixel_noise_is_within_its_bound(tmp_path):
    cams, X = _rig()
    got = _triangulate_exact(cams, X, 0.5, tmp_path)
    assert len(got) >= 0.95 * len(X)
    err = np.array([np.linalg.norm(got[k] - X[k]) for k in got])
    # depth error of a stereo pair: z^2 * sigma / (f * b); 4 views, baseline up to 3 units
    z = np.array([cams[0].to_camera(X[k][None])[0, 2] for k in got])
    bound = z**2 * 0.5 / (cams[0].fx * 1.0)
    assert np.median(err / bound) < 1.0 and np.all(err < 6 * bound)


def test_tentative_matches_are_mutual_and_pass_the_ratio_test():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 128)).astype(np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a[::-1] + rng.normal(0, 0.01, a.shape).astype(np.float32)
    m = tentative_matches(a, b, 0.8)
    assert len(m) == 50 and np.all(m[:, 1] == 49 - m[:, 0])
    twin = np.concatenate([a, a[:10] + 1e-4])  # the first ten have two equally good partners
    noisy = a + rng.normal(0, 0.01, a.shape).astype(np.float32)
    m2 = tentative_matches(noisy, twin, 0.8)
    assert set(m2[:, 0].tolist()) == set(range(10, 50))


# --- reconstructable points on a hand-made scene --------------------------------------------


def _plane_truth(cam) -> GroundTruth:
    """Exact layers of the plane y = 0 seen by `cam` (every pixel hits it)."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width] + 0.5
    d = cam.rays(np.c_[u.ravel(), v.ravel()])
    C = cam.center
    s = -C[1] / d[:, 1]
    P = (C + s[:, None] * d).reshape(cam.height, cam.width, 3)
    z = cam.to_camera(P.reshape(-1, 3))[:, 2].reshape(cam.height, cam.width)
    n = np.broadcast_to([0, -1.0, 0], P.shape)
    return GroundTruth(np.linalg.norm(P - C, axis=2), z, P, n, np.zeros(z.shape))


def _cands(xy):
    xy = np.asarray(xy, float)
    return Candidates(
        xy,
        np.ones(len(xy)),
        np.zeros(len(xy)),
        np.ones(len(xy)),
        np.zeros((len(xy), 128), np.float32),
    )


def test_reconstructable_points_and_gt_correspondences():
    a = look_at((-0.5, -6, 0.2), (0, 0, 0.2), width=160, height=120)
    b = look_at((0.5, -6, 0.2), (0, 0, 0.2), width=160, height=120)
    gts = [_plane_truth(a), _plane_truth(b)]
    P = np.array([[-1.0, 0, 0.5], [0.0, 0, 0.0], [1.0, 0, -0.5], [0.3, 0, 0.9]])
    xa, xb = a.project(P)[0], b.project(P)[0]
    # view a has all four points; view b has the first two exactly, the third 10 px off,
    # and one unrelated candidate
    pools = [_cands(xa), _cands([xb[0], xb[1] + [1.0, 0.5], xb[2] + [10.0, 0], [5.5, 5.5]])]
    truth = SceneTruth.build([a, b], gts, pools)
    assert truth.reconstructable == 2
    ok = truth.correspondences(0, 1, np.array([0, 1, 2, 0]), np.array([0, 1, 2, 1]))
    assert ok.tolist() == [True, True, False, False]


def test_exported_model_reads_back_with_pycolmap(tmp_path):
    from bench.backend import known_pose_model
    from bench.pipeline import export_model

    cams, X = _rig()
    model = known_pose_model(cams, [f"v{k}.png" for k in range(4)], [c.project(X)[0] for c in cams])
    export_model(model, tmp_path / "m")
    back = pycolmap.Reconstruction(str(tmp_path / "m"))
    assert back.num_images() == 4 and back.image(1).num_points2D() == len(X)
    assert (tmp_path / "m" / "points.ply").is_file() and (tmp_path / "m" / "points3D.txt").is_file()
