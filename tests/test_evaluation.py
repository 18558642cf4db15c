"""The metrics and the ground-truth structures, on hand-made cases with known answers."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.spatial.transform import Rotation

from bench.backend.matching import expected_ransac_iterations
from bench.camera import look_at
from bench.evaluation.layers import TruthLayers
from bench.evaluation.metrics import (
    completeness_pct,
    coverage_pct,
    point_error,
    point_metrics,
    rmse,
    runtime_proxy,
)
from bench.evaluation.oracle import matchable_tracks, oracle_select
from bench.evaluation.poses import (
    mean_average_accuracy,
    pose_metrics,
    relative_pose_errors,
    similarity,
)
from bench.evaluation.truth import SceneTruth, Surface
from bench.frontend.features import Candidates

# --- metrics on five hand-made points -------------------------------------------------

TRUE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 1.0]])


def test_point_error_rmse_median_and_completeness_on_five_points():
    surface = Surface(TRUE)
    X = TRUE.copy()
    X[4, 2] += 0.3  # one point 0.3 units off its surface
    e = point_error(X, surface)
    np.testing.assert_allclose(e, [0, 0, 0, 0, 0.3], atol=1e-12)
    assert rmse(e) == pytest.approx(math.sqrt(0.09 / 5))
    assert np.median(e) == 0
    tracks = (TRUE, np.full(5, 0.05))  # each true point a reconstructable track
    assert completeness_pct(X, e, tracks, 0.10) == pytest.approx(80.0)
    assert completeness_pct(X, e, tracks, 0.50) == pytest.approx(80.0)  # accurate, not its own
    far = (np.r_[TRUE, TRUE[:3] + 10], np.full(8, 0.05))
    assert completeness_pct(X, e, far, 0.10) == pytest.approx(50.0)  # 4 of 8 reconstructable
    X[4, 2] = 1.03  # within its track's radius and 0.03 off the surface
    e = point_error(X, surface)
    assert completeness_pct(X, e, tracks, 0.05) == pytest.approx(100.0)
    assert completeness_pct(X, e, tracks, 0.02) == pytest.approx(80.0)
    twice = np.r_[X, X + 0.01]  # every track reconstructed twice counts once: at most 100
    assert completeness_pct(twice, point_error(twice, surface), tracks, 0.05) == 100.0
    empty = (np.zeros((0, 3)), np.zeros(0))
    assert math.isnan(rmse(np.zeros(0))) and math.isnan(completeness_pct(X, e, empty, 0.1))


def test_coverage_of_a_known_layout():
    three_cells = np.array(
        [[1.0, 1.0], [2.0, 2.0], [100.0, 1.0], [630.0, 470.0]]
    )  # 3 cells of 16x12
    every_cell = np.array([[(c + 0.5) * 40, (r + 0.5) * 40] for r in range(12) for c in range(16)])
    cam = look_at((0, 0, 0), (0, 1, 0))  # 640 x 480
    assert coverage_pct([three_cells, every_cell], [cam, cam]) == pytest.approx(
        100 * (3 / 192 + 1) / 2
    )


def test_runtime_proxy_parts():
    r = runtime_proxy([1000, 1000], 5, [([10, 20, 30], [100, 0], [50, 0])])
    assert r["runtime_scoring"] == pytest.approx(10.0)  # 2000 candidates x 5 signals / 1000
    assert r["runtime_matching"] == pytest.approx((200 + 300 + 600) / 1000)
    assert r["runtime_robust"] == pytest.approx(100 * expected_ransac_iterations(0.5) / 1000)
    assert r["runtime_proxy"] == pytest.approx(
        r["runtime_scoring"] + r["runtime_matching"] + r["runtime_robust"]
    )
    # a second match-and-verify pass (the feedback loop's) counts in matching and robust
    two = runtime_proxy([1000, 1000], 5, [([10, 20, 30], [100, 0], [50, 0])] * 2)
    assert two["runtime_matching"] == pytest.approx(2 * r["runtime_matching"])
    assert two["runtime_robust"] == pytest.approx(2 * r["runtime_robust"])
    assert two["runtime_scoring"] == r["runtime_scoring"]


# --- reconstructable points on a hand-made scene --------------------------------------------


def _plane_truth(cam) -> TruthLayers:
    """Exact layers of the plane y = 0 seen by `cam` (every pixel hits it)."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width] + 0.5
    d = cam.rays(np.c_[u.ravel(), v.ravel()])
    C = cam.center
    s = -C[1] / d[:, 1]
    P = (C + s[:, None] * d).reshape(cam.height, cam.width, 3)
    z = cam.to_camera(P.reshape(-1, 3))[:, 2].reshape(cam.height, cam.width)
    n = np.broadcast_to([0, -1.0, 0], P.shape)
    return TruthLayers(np.linalg.norm(P - C, axis=2), z, P, n, np.zeros(z.shape))


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
    assert truth.reconstructable(2) == 2
    ok = truth.correspondences(0, 1, np.array([0, 1, 2, 0]), np.array([0, 1, 2, 1]))
    assert ok.tolist() == [True, True, False, False]


def test_reconstructable_points_per_track_protocol():
    a, b, c = (look_at((x, -6, 0.2), (0, 0, 0.2), width=160, height=120) for x in (-0.5, 0.0, 0.5))
    P = np.array([[-1.0, 0, 0.5], [0.0, 0, 0.0], [1.0, 0, -0.5]])
    # all three points in views a and b; only the first two in view c
    pools = [_cands(a.project(P)[0]), _cands(b.project(P)[0]), _cands(c.project(P[:2])[0])]
    truth = SceneTruth.build([a, b, c], [_plane_truth(v) for v in (a, b, c)], pools)
    assert truth.reconstructable(2) == 3 and truth.reconstructable(3) == 2
    points, radius = truth.track_points(3)  # the two tracks of three views, at their points
    np.testing.assert_allclose(points[np.argsort(points[:, 0])], P[:2], atol=0.05)
    assert (radius > 0).all() and (radius < 0.5).all()  # 3 px at 6 units


def test_accuracy_is_the_share_of_points_within_tau():
    surface = Surface(TRUE)
    X = TRUE.copy()
    X[4, 2] += 0.3
    tracks = (np.r_[TRUE, TRUE + 10], np.full(10, 0.05))
    row = point_metrics(X, surface, tracks)
    assert row["accuracy_pct"] == pytest.approx(80.0) and row["accuracy_pct_0.20"] == 80.0
    assert row["acc_completeness_pct"] == pytest.approx(40.0)  # 4 accurate of 10
    assert math.isnan(point_metrics(np.zeros((0, 3)), surface, tracks)["accuracy_pct"])


# --- the oracle -------------------------------------------------------------------------


def tracks_in_three_views(track: list[np.ndarray], selections: list[np.ndarray]) -> int:
    """How many ground-truth tracks have a selected candidate in at least three views."""
    views_of: dict[int, set[int]] = {}
    for v, (t, s) in enumerate(zip(track, selections)):
        for tid in t[s].tolist():
            views_of.setdefault(tid, set()).add(v)
    return sum(len(vs) >= 3 for vs in views_of.values())


def exact_track_count(track: list[np.ndarray], budget: int) -> int:
    """The most tracks that can have a candidate in three views under the budget, solved
    exactly: maximise sum x_t subject to sum_v y_tv >= 3 x_t and sum_t y_tv <= min(B, N_v)."""
    spans: dict[int, list[int]] = {}
    for v, t in enumerate(track):
        for tid in np.unique(t).tolist():
            spans.setdefault(tid, []).append(v)
    tracks = [t for t in sorted(spans) if len(spans[t]) >= 3]
    if not tracks:
        return 0
    y = [(i, v) for i, t in enumerate(tracks) for v in spans[t]]
    n_x, n = len(tracks), len(tracks) + len(y)
    rows_need = np.zeros((n_x, n))
    rows_need[np.arange(n_x), np.arange(n_x)] = 3
    rows_room = np.zeros((len(track), n))
    for k, (i, v) in enumerate(y):
        rows_need[i, n_x + k] = -1
        rows_room[v, n_x + k] = 1
    room = [min(budget, len(t)) for t in track]
    res = milp(
        c=np.r_[-np.ones(n_x), np.zeros(len(y))],
        constraints=[LinearConstraint(rows_need, -np.inf, 0), LinearConstraint(rows_room, 0, room)],
        integrality=np.ones(n),
        bounds=Bounds(0, 1),
    )
    return int(round(-res.fun))


def test_oracle_picks_the_candidates_of_the_three_view_tracks():
    """Four views of five candidates: tracks 0 and 1 span three views, track 2 two views,
    the rest are singletons. With a budget of two per view (one per view where only one
    three-view track is present), exactly the three-view tracks' candidates are chosen."""
    track = [
        np.array([0, 1, 2, 10, 11]),
        np.array([0, 1, 2, 12, 13]),
        np.array([0, 14, 15, 16, 17]),
        np.array([1, 18, 19, 20, 21]),
    ]
    response = [np.arange(5, 0, -1.0)[::-1] for _ in track]  # singletons are the strongest
    sel = oracle_select(track, response, 2)
    assert [sorted(t[s].tolist()) for t, s in zip(track, sel)][:2] == [[0, 1], [0, 1]]
    assert tracks_in_three_views(track, sel) == 2 == exact_track_count(track, 2)
    assert all(len(s) == 2 and len(set(s.tolist())) == 2 for s in sel)


def test_oracle_greedy_is_close_to_the_exact_optimum():
    rng = np.random.default_rng(0)
    got = best = 0
    for _ in range(25):
        n, n_tracks, budget = rng.integers(10, 40), rng.integers(5, 30), int(rng.integers(2, 8))
        track = [rng.integers(0, n_tracks, n) for _ in range(6)]
        sel = oracle_select(track, [rng.random(n) for _ in range(6)], budget)
        assert all(len(s) == min(budget, n) for s in sel)
        got += tracks_in_three_views(track, sel)
        best += exact_track_count(track, budget)
    assert got <= best and got >= 0.95 * best, (got, best)


def test_matchable_tracks_need_ground_truth_and_matching_descriptors():
    a = look_at((-0.5, -6, 0.2), (0, 0, 0.2), width=160, height=120)
    b = look_at((0.5, -6, 0.2), (0, 0, 0.2), width=160, height=120)
    P = np.array([[-1.0, 0, 0.5], [0.0, 0, 0.0], [1.0, 0, -0.5]])
    rng = np.random.default_rng(0)
    desc = rng.normal(size=(4, 128)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    pa, pb = _cands(a.project(P)[0]), _cands(b.project(P)[0])
    pa.descriptors[:] = desc[:3]
    pb.descriptors[:] = desc[[0, 1, 3]]  # the third point looks different in view b
    truth = SceneTruth.build([a, b], [_plane_truth(a), _plane_truth(b)], [pa, pb])
    ta, tb = matchable_tracks(truth, [pa, pb], 0.8)
    assert ta[0] == tb[0] and ta[1] == tb[1] and ta[2] != tb[2]

    # computed once per scene: equal pools (another geometry's copy) give the same result
    # object; other descriptors or another truth compute again, as the function would
    copies = [replace(pa, descriptors=pa.descriptors.copy()), replace(pb)]
    assert matchable_tracks(truth, copies, 0.8) is matchable_tracks(truth, [pa, pb], 0.8)
    pb.descriptors[:] = desc[[0, 3, 2]]
    again = matchable_tracks(truth, [pa, pb], 0.8)
    fresh = matchable_tracks.__wrapped__(truth, [pa, pb], 0.8)
    assert [t.tolist() for t in again] == [t.tolist() for t in fresh] != [ta.tolist(), tb.tolist()]
    other = SceneTruth.build([a, b], [_plane_truth(a), _plane_truth(b)], [pa, pb])
    assert matchable_tracks(other, [pa, pb], 0.8) is not again


# --- pose accuracy of the sfm task -------------------------------------------------------


def _arc_rig():
    return [
        look_at((8 * np.cos(a), 8 * np.sin(a), 2.0), (0, 0, 1.0)) for a in np.linspace(-0.6, 0.6, 6)
    ]


def test_maa_of_the_rig_against_itself_and_with_one_camera_turned_by_5_degrees():
    rig = _arc_rig()
    est = {k: (c.R, c.t) for k, c in enumerate(rig)}
    assert mean_average_accuracy(relative_pose_errors(est, rig)) == 1.0
    turn = Rotation.from_euler("z", 5, degrees=True).as_matrix()  # about camera 2's own axis
    est[2] = (turn @ rig[2].R, turn @ rig[2].t)
    # By hand: the 5 pairs with camera 2 have a rotation error of exactly 5 degrees (and a
    # translation-direction error of at most 5), so they pass the thresholds 6..10 (5 of
    # 10); the other 10 pairs pass all 10. mAA = (10 * 10 + 5 * 5) / (15 * 10).
    assert mean_average_accuracy(relative_pose_errors(est, rig)) == pytest.approx(125 / 150)


def test_unregistered_views_count_as_failed_pairs_never_nan():
    rig = _arc_rig()
    row, sim = pose_metrics({}, rig)
    assert row["maa"] == 0.0 and row["registered_views"] == 0 and sim is None
    half = {k: (rig[k].R, rig[k].t) for k in range(3)}  # 3 of 15 pairs registered, exact
    row, sim = pose_metrics(half, rig)
    assert row["maa"] == pytest.approx(3 / 15) and row["cam_center_err"] < 1e-9


def test_similarity_alignment_recovers_a_known_transform():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(10, 3))
    R = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    s, R_est, t_est = similarity(X, 2.5 * X @ R.T + [1.0, 2.0, 3.0])
    assert s == pytest.approx(2.5) and np.allclose(R_est, R) and np.allclose(t_est, [1, 2, 3])
