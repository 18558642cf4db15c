"""Evaluation against the ground truth: the only stage that reads it.

A render entry has every layer. A dataset (`bench.evaluation.layers`) has the poses,
and optionally a point cloud (point accuracy) and per-pixel truth (match precision,
ground-truth tracks, completeness); a metric whose truth is missing is NaN.

Track protocol (`bench.backend.reconstruction`): the headline scores points whose tracks
span at least three views (`multiview`, COLMAP's default point triangulation); keeping
two-view tracks (`twoview`) is reported in its own table only (why: CHANGELOG, 0.1).

Metrics, for one run (scene, seed, method, budget, task, protocol):

* point error e(X) = min_s |X - s| over the ground-truth surface samples s (the world
  positions of every single-surface pixel of all six views).
* rmse = sqrt(mean_X e(X)^2) over all reconstructed points (outliers count);
  median_error = median_X e(X).
* ground-truth correspondence: candidate k of view i and candidate l of view j correspond
  when P_k (the 3D point under k's pixel) is visible in j (in front, inside, and its depth
  within 1% + 0.01 of view j's z-map there) and projects within 3 px of l, or the same
  with i and j swapped. Candidates on occlusion edges (mixed pixels) have no P_k.
* ground-truth tracks of a scene: connected components of the correspondence graph over
  the whole candidate pool (each candidate linked to its nearest corresponding candidate in
  each other view). The reconstructable points of a track protocol are the tracks that
  span at least as many views as the protocol asks of a point (three for `multiview`, two
  for `twoview`). The same for every policy.
* acc_completeness_pct@tau = 100 * #{reconstructable tracks T : some X with e(X) < tau
  lies within T's radius of T's point} / #reconstructable tracks, for tau in 0.02, 0.05,
  0.10 (the headline) and 0.20 scene units: each ground-truth point reconstructed counts
  once, so it is at most 100 (a track's point: the mean ground-truth point of its
  candidates; its radius: 3 px at its depth; an accurate X counts for its nearest track).
* accuracy_pct@tau = 100 * #{X : e(X) < tau} / #{X}: the share of the reconstructed points
  within tau (ETH3D's accuracy beside its completeness), for the same four tau.
* inlier_pct = 100 * verified matches / tentative matches, summed over all pairs.
* match_precision_pct = 100 * ground-truth-correct verified matches / verified matches.
* coverage_pct = 100 * mean over views of the share of the 16 x 12 image grid's cells that
  hold at least one selected feature.
* mean_track_length = mean number of views observing a point; mean_tri_angle_deg = mean
  over points of the largest angle between two of its viewing rays.
* runtime_proxy (thousands of elementary operations, deterministic) = scoring + matching
  + robust, where scoring = sum_views N_pool * (signals the policy reads), matching =
  sum_pairs n_i * n_j descriptor comparisons, robust = sum_pairs M_pair * T(w_pair) with
  M the tentative matches, w the measured inlier ratio and T(w) = log(0.001) /
  log(1 - w^5) the expected 5-point RANSAC iterations at 99.9% confidence, clipped
  to COLMAP's RANSAC bounds [100, 10000]. A policy that matches and verifies more than
  once (`adaptive-loop`) has every pass counted in matching and robust.
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree

from bench.backend.matching import PairMatches, expected_ransac_iterations
from bench.camera import Camera
from bench.evaluation.truth import SceneTruth, Surface
from bench.frontend.features import Candidates, tile_of
from bench.vocabulary import DEGREES, PERCENT, Metric, declare_metric

THRESHOLDS = (0.02, 0.05, 0.10, 0.20)
COVERAGE_GRID = (16, 12)
SUFFIXES = tuple("" if tau == 0.10 else f"_{tau:.2f}" for tau in THRESHOLDS)
"""The names' suffix of each threshold (0.10, the headline's, has none)."""

for _metric in (
    Metric("views", doc="views in the scene (a row's bookkeeping)"),
    Metric("render_s_per_view", doc="the render entry's mean seconds per view"),
    Metric("wall_ms", lower_better=True, doc="the unit's measured milliseconds, scoring aside"),
    Metric("task_ms", lower_better=True, doc="the task's reconstruction, milliseconds"),
    Metric("tentative_matches", peers=True),
    Metric("verified_matches", peers=True),
    Metric("inlier_pct", PERCENT, title="Inlier %", peers=True),
    Metric("match_precision_pct", PERCENT),
    Metric("coverage_pct", PERCENT, title="Coverage %", peers=True),
    Metric("keypoints_per_view", peers=True, doc="a peer's keypoints per view (COLMAP's)"),
    Metric("runtime_proxy", lower_better=True, title="Runtime proxy (k ops)"),
    Metric("runtime_scoring"),
    Metric("runtime_matching"),
    Metric("runtime_robust"),
    Metric("reconstructable"),
    Metric("points", failure=0.0),
    Metric("rmse", lower_better=True, title="RMSE (scene units)", of_model=True),
    Metric("median_error", lower_better=True, title="Median error (scene units)", of_model=True),
    Metric("mean_track_length"),
    Metric("mean_tri_angle_deg", DEGREES),
    Metric(
        "completeness_vs_oracle_pct",
        title="Completeness, % of the oracle's",
        share_of="acc_completeness_pct",
        doc="the report's: a run's completeness as a share of the oracle's",
    ),
):
    declare_metric(_metric)
for _suffix, _tau in zip(SUFFIXES, THRESHOLDS):
    declare_metric(
        Metric(
            f"accuracy_pct{_suffix}",
            PERCENT,
            title=f"Accuracy % (points with e < {_tau:.2f})" if not _suffix else "",
        )
    )
    declare_metric(
        Metric(
            f"acc_completeness_pct{_suffix}",
            PERCENT,
            failure=0.0,
            title=f"Acc. completeness % (e < {_tau:.2f})" if not _suffix else "",
        )
    )


def point_error(X: np.ndarray, surface: Surface) -> np.ndarray:
    """Distance from each point (N, 3) to the nearest ground-truth surface sample."""
    return surface.distances(X) if len(X) else np.zeros(0)


def rmse(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors**2))) if len(errors) else math.nan


def completeness_pct(
    X: np.ndarray, errors: np.ndarray, tracks: tuple[np.ndarray, np.ndarray], tau: float
) -> float:
    """100 x the reconstructable tracks (their points and radii, `SceneTruth.track_points`)
    that an accurate point (error below `tau`) lies within the radius of, each counted once
    (by its nearest track), / the reconstructable tracks: at most 100 by construction."""
    points, radius = tracks
    if not len(points):
        return math.nan
    accurate = np.asarray(X, np.float64).reshape(-1, 3)[np.asarray(errors) < tau]
    if not len(accurate):
        return 0.0
    d, nearest = cKDTree(points).query(accurate)
    return 100.0 * len(np.unique(nearest[d <= radius[nearest]])) / len(points)


def coverage_pct(xy_per_view: list[np.ndarray], cams: list[Camera], grid=COVERAGE_GRID) -> float:
    shares = []
    for xy, cam in zip(xy_per_view, cams):
        tiles = tile_of(xy, cam.width, cam.height, grid)
        shares.append(len(np.unique(tiles)) / (grid[0] * grid[1]))
    return 100.0 * float(np.mean(shares))


def runtime_proxy(pool_sizes, n_signals: int, passes) -> dict[str, float]:
    """The proxy of the module docstring; `passes`: (selected sizes per view, tentative and
    verified matches per pair) of every match-and-verify pass."""
    scoring = sum(pool_sizes) * n_signals
    matching = sum(a * b for sizes, _, _ in passes for a, b in combinations(sizes, 2))
    robust = sum(
        m * expected_ransac_iterations(v / m)
        for _, tentative, verified in passes
        for m, v in zip(tentative, verified)
        if m
    )
    parts = {
        "runtime_scoring": scoring / 1e3,
        "runtime_matching": matching / 1e3,
        "runtime_robust": robust / 1e3,
    }
    return {"runtime_proxy": sum(parts.values()), **parts}


def match_metrics(
    truth: SceneTruth,
    pools: list[Candidates],
    selections: list[np.ndarray],
    pairs: list[PairMatches],
    n_signals: int,
    earlier: list = (),
) -> dict[str, float]:
    """The metrics of the selection and its matches (shared by every task of a run);
    `earlier`: (selected sizes, tentative, verified per pair) of the match-and-verify passes
    a feedback policy made before its final one, counted in the runtime proxy."""
    row: dict[str, float] = {}
    tentative = [len(p.tentative) for p in pairs]
    verified = [len(p.verified) for p in pairs]
    row["tentative_matches"], row["verified_matches"] = sum(tentative), sum(verified)
    row["inlier_pct"] = 100.0 * sum(verified) / sum(tentative) if sum(tentative) else math.nan
    if truth.per_pixel and sum(verified):
        correct = sum(
            int(
                truth.correspondences(
                    p.i, p.j, selections[p.i][p.verified[:, 0]], selections[p.j][p.verified[:, 1]]
                ).sum()
            )
            for p in pairs
            if len(p.verified)
        )
        row["match_precision_pct"] = 100.0 * correct / sum(verified)
    else:
        row["match_precision_pct"] = math.nan
    row["coverage_pct"] = coverage_pct(
        [pools[v].xy[s] for v, s in enumerate(selections)], truth.cams
    )
    passes = [*earlier, ([len(s) for s in selections], tentative, verified)]
    row |= runtime_proxy([len(p) for p in pools], n_signals, passes)
    return row


def point_metrics(
    X: np.ndarray, surface: Surface | None, tracks: tuple[np.ndarray, np.ndarray] | None
) -> dict[str, float]:
    """Accuracy of reconstructed points X (N, 3): rmse, median error, accuracy within each
    tau and, given the reconstructable tracks (`SceneTruth.track_points`), completeness
    within each tau (NaN where the surface or the tracks are unknown)."""
    if surface is None:
        row = {"points": len(X), "rmse": math.nan, "median_error": math.nan}
        for tau in THRESHOLDS:
            suffix = "" if tau == 0.10 else f"_{tau:.2f}"
            row[f"accuracy_pct{suffix}"] = row[f"acc_completeness_pct{suffix}"] = math.nan
        return row
    e = point_error(X, surface)
    row: dict[str, float] = {"points": len(X), "rmse": rmse(e)}
    row["median_error"] = float(np.median(e)) if len(e) else math.nan
    for tau in THRESHOLDS:
        suffix = "" if tau == 0.10 else f"_{tau:.2f}"
        row[f"accuracy_pct{suffix}"] = 100.0 * float(np.mean(e < tau)) if len(e) else math.nan
        row[f"acc_completeness_pct{suffix}"] = (
            math.nan if tracks is None else completeness_pct(X, e, tracks, tau)
        )
    return row


def track_metrics(model) -> dict[str, float]:
    """Mean track length (views per point) and mean largest triangulation angle."""
    pts = list(model.points3D.values()) if model is not None else []
    if not pts:
        return {"mean_track_length": math.nan, "mean_tri_angle_deg": math.nan}
    centres = {k: model.images[k].projection_center() for k in model.reg_image_ids()}
    lengths, angles = [], []
    for p in pts:
        ids = [el.image_id for el in p.track.elements]
        lengths.append(len(ids))
        rays = np.array([centres[k] - p.xyz for k in ids])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        angles.append(np.degrees(np.arccos(np.clip((rays @ rays.T).min(), -1, 1))))
    return {
        "mean_track_length": float(np.mean(lengths)),
        "mean_tri_angle_deg": float(np.mean(angles)),
    }


def model_points(model) -> np.ndarray:
    """The 3D points of a COLMAP model (or none), as (N, 3)."""
    pts = model.points3D.values() if model is not None else []
    return np.array([p.xyz for p in pts]).reshape(-1, 3)


def evaluate_known_pose(truth: SceneTruth, model, min_views: int) -> dict[str, float]:
    """The point metrics of a known-pose model, against the reconstructable points of its
    track protocol (tracks spanning at least `min_views` views)."""
    tracks = truth.track_points(min_views)
    return (
        {"reconstructable": math.nan if tracks is None else len(tracks[0])}
        | point_metrics(model_points(model), truth.surface, tracks)
        | track_metrics(model)
    )
