"""The COLMAP back end (matching, verification, triangulation) on hand-made geometry."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pycolmap
import pytest

from bench.backend.matching import (
    BackendConfig,
    PairMatches,
    expected_ransac_iterations,
    verify,
)
from bench.backend.reconstruction import known_pose_task, mapping_task, triangulate
from bench.evaluation.poses import pose_metrics, registered_poses
from bench.frontend.features import descriptor_distances, nearest_two, tentative_matches
from tests.conftest import synthetic_rig


def _names(n: int) -> list[str]:
    return [f"view_{k:02d}.png" for k in range(n)]


# --- synthetic two-view geometry ----------------------------------------------------------


def test_verification_removes_planted_outliers():
    cams, X = synthetic_rig()
    xa, xb = cams[0].project(X)[0], cams[2].project(X)[0]
    rng = np.random.default_rng(0)
    planted = np.c_[rng.uniform(0, 640, (40, 1)), rng.uniform(0, 480, (40, 1))]
    xb = np.concatenate([xb, planted])
    xa = np.concatenate([xa, rng.uniform(0, 480, (40, 2))])
    matches = np.c_[np.arange(190), np.arange(190)]
    inliers, config, _ = verify(cams[0], xa, cams[2], xb, matches, BackendConfig())
    kept = set(inliers[:, 0].tolist())
    assert config == "CALIBRATED"
    assert len(kept & set(range(150))) >= 145
    assert len(kept & set(range(150, 190))) <= 4


def _triangulate_exact(cams, X, noise_px):
    rng = np.random.default_rng(1)
    xy = [c.project(X)[0] + rng.normal(0, noise_px, (len(X), 2)) for c in cams]
    ids = np.arange(len(X))
    pairs = [
        PairMatches(i, j, np.c_[ids, ids], np.c_[ids, ids], "CALIBRATED")
        for i in range(4)
        for j in range(i + 1, 4)
    ]
    names = [f"view_{k:02d}.png" for k in range(4)]
    model = triangulate(cams, names, xy, pairs, BackendConfig())
    got = {}
    for p in model.points3D.values():
        obs = {el.image_id: el.point2D_idx for el in p.track.elements}
        got[obs[min(obs)]] = p.xyz
    return got


def test_triangulation_with_known_poses_recovers_exact_points():
    cams, X = synthetic_rig()
    got = _triangulate_exact(cams, X, 0.0)
    assert len(got) == len(X)
    err = np.array([np.linalg.norm(got[k] - X[k]) for k in got])
    # COLMAP's database stores keypoints as float32 (~4e-5 px at x = 640), which alone
    # moves a point at depth 8 by up to ~1e-6 units: that is the floor of "exact" here.
    assert np.median(err) < 1e-6 and err.max() < 5e-6


def test_triangulation_error_under_half_pixel_noise_is_within_its_bound():
    cams, X = synthetic_rig()
    got = _triangulate_exact(cams, X, 0.5)
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


def test_the_two_nearest_are_what_a_partition_finds_with_ties_and_infinities():
    rng = np.random.default_rng(3)
    D = rng.integers(0, 4, (40, 7)).astype(np.float32)  # many ties
    D[5] = np.inf
    D[6, 2:] = np.inf
    two = np.partition(D, 1, axis=1)[:, :2]
    col, first, second = nearest_two(D.copy())
    assert np.array_equal(first, two[:, 0]) and np.array_equal(second, two[:, 1])
    assert np.array_equal(col, D.argmin(1))


def test_tentative_matches_are_mutual_argmins_where_distances_tie():
    """Binary descriptors tie often: a row is matched only where it is its nearest column's
    argmin (the first row holding that column's minimum), as the definition reads."""
    rng = np.random.default_rng(4)
    matched = tied = 0
    for _ in range(20):
        base = rng.integers(0, 256, (6, 32), np.uint8)  # six descriptors, slightly flipped
        a, b = base[rng.integers(0, 6, 60)], base[rng.integers(0, 6, 45)]
        a[rng.random(a.shape) < 0.05] ^= 1
        b[rng.random(b.shape) < 0.05] ^= 1
        D = descriptor_distances(a, b)
        tied += int(((D == D.min(0)).sum(0) > 1).sum())
        two = np.partition(D, 1, axis=1)[:, :2]
        rows = np.arange(len(a))
        keep = (D.argmin(0)[D.argmin(1)] == rows) & (two[:, 0] < 1.0 * two[:, 1])
        expected = np.stack([rows[keep], D.argmin(1)[keep]], 1)
        assert np.array_equal(tentative_matches(a, b, 1.0), expected)
        matched += len(expected)
    assert matched > 50 and tied > 200  # the case is one of ties, and matches are found


def test_expected_ransac_iterations():
    assert expected_ransac_iterations(0.5) == pytest.approx(math.log(0.001) / math.log(1 - 0.5**5))
    assert expected_ransac_iterations(1.0) == 100.0 and expected_ransac_iterations(0.0) == 10000.0


def test_a_two_view_outlier_is_dropped_by_multiview_and_kept_by_twoview():
    """150 points seen by all four cameras, plus one wrong match seen by two: its second
    observation lies on the epipolar line of the first, at the image of a point 3 units
    deeper, so it triangulates cleanly (no reprojection error) far from any true point."""
    cams, X = synthetic_rig()
    xy = [c.project(X)[0] for c in cams]
    ray = cams[0].rays(xy[0][:1])[0]
    wrong = cams[0].center + (np.linalg.norm(X[0] - cams[0].center) + 3.0) * ray
    xy[0] = np.vstack([xy[0], xy[0][:1]])
    xy[1] = np.vstack([xy[1], cams[1].project(wrong[None])[0]])
    ids = np.arange(len(X))
    pairs = []
    for i in range(4):
        for j in range(i + 1, 4):
            m = np.c_[ids, ids]
            if (i, j) == (0, 1):
                m = np.vstack([m, [len(X), len(X)]])
            pairs.append(PairMatches(i, j, m, m, "CALIBRATED"))
    names = [f"view_{k:02d}.png" for k in range(4)]
    found = {}
    for protocol in ("multiview", "twoview"):
        model = triangulate(cams, names, xy, pairs, BackendConfig(), protocol)
        P = np.array([p.xyz for p in model.points3D.values()])
        found[protocol] = (len(P), np.linalg.norm(P - wrong, axis=1).min())
    assert found["multiview"][0] == len(X) and found["multiview"][1] > 1.0
    assert found["twoview"][0] == len(X) + 1 and found["twoview"][1] < 1e-3


def _matched_rig(tmp_path, views):
    cams, X = synthetic_rig()
    cams = [cams[k] for k in views]
    xy = [c.project(X)[0] for c in cams]
    ids = np.arange(len(X))
    pairs = [
        PairMatches(i, j, np.c_[ids, ids], np.c_[ids, ids], "CALIBRATED")
        for i in range(len(cams))
        for j in range(i + 1, len(cams))
    ]
    for n in _names(len(cams)):  # grey views: a point coloured from them would be 200
        cv2.imwrite(str(tmp_path / n), np.full((480, 640, 3), 200, np.uint8))
    return cams, xy, pairs


def test_a_hand_made_two_view_scene_is_registered_and_scored(tmp_path):
    cams, xy, pairs = _matched_rig(tmp_path, [0, 3])
    # COLMAP's default mapper ignores two-view tracks, so only the twoview protocol can map
    # a scene seen by two views
    assert mapping_task(cams, _names(len(cams)), xy, pairs, BackendConfig()).model is None
    rec = mapping_task(cams, _names(len(cams)), xy, pairs, BackendConfig(), "twoview")
    assert rec.failure is None and rec.model.num_reg_images() == 2
    est = registered_poses(rec.model, {n: k for k, n in enumerate(_names(2))})
    row, _ = pose_metrics(est, cams)
    assert row["registered_views"] == 2 and row["maa"] == 1.0
    assert row["median_pose_err_deg"] < 0.01
    # with four views, COLMAP's default mapper (multiview) registers them all
    cams, xy, pairs = _matched_rig(tmp_path, [0, 1, 2, 3])
    rec = mapping_task(cams, _names(len(cams)), xy, pairs, BackendConfig())
    est = registered_poses(rec.model, {n: k for k, n in enumerate(_names(4))})
    assert pose_metrics(est, cams)[0]["maa"] == 1.0


def test_neither_task_reads_the_images_to_colour_its_points(tmp_path):
    """COLMAP colours the points from the views it is given (most of a call on large
    photographs); no metric reads a colour, so the back end gives it none to read."""
    cams, xy, pairs = _matched_rig(tmp_path, [0, 1, 2, 3])
    mapped = mapping_task(cams, _names(4), xy, pairs, BackendConfig()).model
    known = known_pose_task(cams, _names(4), xy, pairs, BackendConfig(), "multiview").model
    for model in (mapped, known):
        colours = np.array([p.color for p in model.points3D.values()])
        assert len(colours) > 100 and not colours.any()


def test_a_rig_the_defaults_map_is_mapped_once_without_the_forward_start(tmp_path, monkeypatch):
    """The forward start (`FORWARD_START`) is a second try, never taken where COLMAP's
    defaults register the views."""
    from bench.backend import reconstruction

    cams, xy, pairs = _matched_rig(tmp_path, [0, 1, 2, 3])
    calls, real = [], reconstruction._incremental
    monkeypatch.setattr(
        reconstruction,
        "_incremental",
        lambda db, opts: calls.append(opts.mapper.init_min_tri_angle) or real(db, opts),
    )
    rec = mapping_task(cams, _names(4), xy, pairs, BackendConfig())
    assert rec.model is not None and rec.model.num_reg_images() == 4
    assert calls == [pycolmap.IncrementalMapperOptions().init_min_tri_angle]


def test_a_mapping_without_matches_is_a_recorded_failure(tmp_path):
    cams, xy, pairs = _matched_rig(tmp_path, [0, 1, 2])
    empty = [PairMatches(p.i, p.j, p.tentative[:0], p.verified[:0], "UNDEFINED") for p in pairs]
    rec = mapping_task(cams, _names(len(cams)), xy, empty, BackendConfig())
    assert rec.model is None and "no pair of views has verified matches" in rec.failure
    row, _ = pose_metrics(registered_poses(rec.model, {}), cams)
    assert row["maa"] == 0.0


def test_the_hard_cap_keeps_the_largest_scales_ties_by_index_in_colmaps_order():
    from bench.backend.peers import hard_cap, keypoint_scales

    # COLMAP affine keypoints (x, y, a11, a12, a21, a22): scale s rotated by 30 degrees
    c, s_ = math.cos(math.pi / 6), math.sin(math.pi / 6)
    scales = np.array([1.0, 4.0, 2.0, 4.0, 0.5, 2.0, 8.0])
    kps = np.array([[k, k, s * c, -s * s_, s * s_, s * c] for k, s in enumerate(scales)])
    np.testing.assert_allclose(keypoint_scales(kps), scales)
    assert hard_cap(kps, 3).tolist() == [1, 3, 6]
    assert hard_cap(kps, 4).tolist() == [1, 2, 3, 6]  # the tie at scale 2: the lower index
    assert hard_cap(kps, 100).tolist() == list(range(7))


def test_a_forward_drive_is_mapped_from_a_forward_first_pair_only(tmp_path, monkeypatch):
    # six views 1 m apart driving along their optical axis (y), 400 points 8-40 m ahead:
    # every pair moves along the axis and its angles are small, so COLMAP's first-pair
    # tests (16 degrees, relaxed to 4 by itself; motion off the axis) refuse every pair
    from bench.backend import reconstruction
    from bench.camera import look_at

    cams = [look_at((0.0, y, 1.5), (0.0, y + 10.0, 1.5)) for y in range(6)]
    rng = np.random.default_rng(5)
    X = np.c_[rng.uniform(-12, 12, 400), rng.uniform(13, 45, 400), rng.uniform(-2, 8, 400)]
    seen = np.all([c.project(X)[1] > 0 for c in cams], axis=0)
    X = X[seen & np.all([_inside(c, X) for c in cams], axis=0)]
    xy = [c.project(X)[0] for c in cams]
    ids = np.arange(len(X))
    pairs = [
        PairMatches(i, j, np.c_[ids, ids], np.c_[ids, ids], "CALIBRATED")
        for i in range(6)
        for j in range(i + 1, 6)
    ]
    for n in _names(6):
        cv2.imwrite(str(tmp_path / n), np.zeros((480, 640, 3), np.uint8))
    rec = mapping_task(cams, _names(6), xy, pairs, BackendConfig())
    est = registered_poses(rec.model, {n: k for k, n in enumerate(_names(6))})
    row, _ = pose_metrics(est, cams)
    assert row["registered_views"] == 6 and row["maa"] > 0.9
    # without the second start (COLMAP's defaults again), nothing is mapped
    monkeypatch.setattr(
        reconstruction,
        "FORWARD_START",
        {"init_min_tri_angle": 16.0, "init_max_forward_motion": 0.95},
    )
    rec = mapping_task(cams, _names(6), xy, pairs, BackendConfig())
    assert rec.model is None and "the mapper registered" in rec.failure


def test_the_forward_start_maps_a_first_pair_of_under_one_degree(monkeypatch):
    """COLMAP halves the first pair's angle twice by itself where it maps no model (2 to 1
    to 0.5 degrees from `FORWARD_START`; 4 to 2 to 1 from 4): three views 0.5 m apart
    along their optical axis, 60 points 4-8 m ahead among 300 at 20-40 m, whose widest
    pair's median triangulation angle is 0.65 degrees, are mapped from 2 and not from 4."""
    from bench.backend import reconstruction
    from bench.camera import look_at

    cams = [look_at((0.0, y, 1.5), (0.0, y + 10.0, 1.5)) for y in (0.0, 0.5, 1.0)]
    rng = np.random.default_rng(5)
    d = np.r_[rng.uniform(4, 8, 60), rng.uniform(20, 40, 300)]
    X = np.c_[rng.uniform(-0.55, 0.55, 360) * d, d + 1, 1.5 + rng.uniform(-0.4, 0.4, 360) * d]
    X = X[np.all([_inside(c, X) for c in cams], axis=0)]
    rays = [X - c.center for c in cams[::2]]
    cos = np.sum(rays[0] * rays[1], 1) / np.prod([np.linalg.norm(r, axis=1) for r in rays], 0)
    assert 0.5 < np.degrees(np.median(np.arccos(cos))) < 1.0
    xy, ids = [c.project(X)[0] for c in cams], np.arange(len(X))
    pairs = [
        PairMatches(i, j, np.c_[ids, ids], np.c_[ids, ids], "CALIBRATED")
        for i, j in [(0, 1), (0, 2), (1, 2)]
    ]
    rec = mapping_task(cams, _names(3), xy, pairs, BackendConfig())
    est = registered_poses(rec.model, {n: k for k, n in enumerate(_names(3))})
    row, _ = pose_metrics(est, cams)
    assert row["registered_views"] == 3 and row["maa"] > 0.9
    four = {**reconstruction.FORWARD_START, "init_min_tri_angle": 4.0}
    monkeypatch.setattr(reconstruction, "FORWARD_START", four)
    rec = mapping_task(cams, _names(3), xy, pairs, BackendConfig())
    assert rec.model is None and "the mapper registered" in rec.failure


def _inside(cam, X) -> np.ndarray:
    uv = cam.project(X)[0]
    return (uv[:, 0] > 0) & (uv[:, 0] < cam.width) & (uv[:, 1] > 0) & (uv[:, 1] < cam.height)
