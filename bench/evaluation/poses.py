"""Pose accuracy of the `sfm` task against the rig (the render entry's ground-truth poses).

For every pair of views (i, j), the relative pose cam_j_from_cam_i = (R_j R_i^T,
t_j - R_j R_i^T t_i) is compared with the rig's:

* rotation error: the angle of R_est^T R_gt;
* translation-direction error: arccos |t_est . t_gt| of the unit translations (the sign
  and scale of a relative translation are not observable from two views);
* pose error: the larger of the two; a pair with an unregistered view has an infinite one.

mAA is the mean over the thresholds 1, 2, ..., 10 degrees of the share of all pairs whose
pose error is below the threshold: the Image Matching Benchmark's metric (Jin et al.,
"Image Matching across Wide Baselines: From Paper to Practice", IJCV 2021). Errors are
rounded to 1e-6 degrees before the comparison, so that floating-point noise does not decide
a pair that sits on a threshold. A failed reconstruction scores 0, never NaN.

The registered camera centres are aligned to the rig's by a similarity (Umeyama 1991);
`cam_center_err` is the mean distance after it, in scene units (three or more registered
views; NaN below), and the model's points are moved by the same similarity before their
ground-truth accuracy is measured.
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np

from bench.camera import Camera
from bench.evaluation.metrics import model_points, point_metrics, track_metrics
from bench.evaluation.truth import SceneTruth
from bench.vocabulary import DEGREES, FRACTION, Metric, declare_metric

MAA_THRESHOLDS_DEG = tuple(range(1, 11))

for _metric in (
    Metric("maa", FRACTION, title="SfM pose mAA (1-10 deg), unknown poses", failure=0.0),
    Metric("registered_views", failure=0.0),
    Metric("median_pose_err_deg", DEGREES, lower_better=True),
    Metric("cam_center_err", lower_better=True),
    Metric("mean_reproj_px", lower_better=True),
):
    declare_metric(_metric)


def _angle_deg(cos: float) -> float:
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def relative_pose_errors(
    est: dict[int, tuple[np.ndarray, np.ndarray]], rig: list[Camera]
) -> list[tuple[float, float]]:
    """(rotation error, translation-direction error) in degrees for every pair of views;
    `est` maps a view to its estimated (R, t) cam_from_world; a missing view is unregistered."""
    out = []
    for i, j in combinations(range(len(rig)), 2):
        if i not in est or j not in est:
            out.append((math.inf, math.inf))
            continue
        (Ri, ti), (Rj, tj) = est[i], est[j]
        R, t = Rj @ Ri.T, tj - Rj @ Ri.T @ ti
        Rg = rig[j].R @ rig[i].R.T
        tg = rig[j].t - Rg @ rig[i].t
        rot = _angle_deg((np.trace(R.T @ Rg) - 1) / 2)
        tra = _angle_deg(abs(float(t @ tg)) / max(np.linalg.norm(t) * np.linalg.norm(tg), 1e-15))
        out.append((rot, tra))
    return out


def mean_average_accuracy(errors: list[tuple[float, float]]) -> float:
    """mAA over 1..10 degrees of the pose error max(rotation, translation direction)."""
    pose = np.round([max(e) for e in errors], 6)
    return float(np.mean([np.mean(pose < th) for th in MAA_THRESHOLDS_DEG])) if len(pose) else 0.0


def similarity(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) minimising |s R src + t - dst|^2 (Umeyama), for (N, 3) point sets."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    var = (a**2).sum() / len(src)
    s = float(np.trace(np.diag(S) @ D) / var) if var > 0 else 1.0
    return s, R, mu_d - s * R @ mu_s


def pose_metrics(
    est: dict[int, tuple[np.ndarray, np.ndarray]], rig: list[Camera]
) -> tuple[dict, tuple | None]:
    """The pose metrics of one sfm model, and the similarity that aligns it to the rig (None
    with fewer than three registered views)."""
    errors = relative_pose_errors(est, rig)
    finite = [max(e) for e in errors if math.isfinite(e[0])]
    row = {
        "registered_views": len(est),
        "maa": mean_average_accuracy(errors),
        "median_pose_err_deg": float(np.median(finite)) if finite else math.nan,
        "cam_center_err": math.nan,
    }
    if len(est) < 3:
        return row, None
    views = sorted(est)
    centres = np.array([-est[v][0].T @ est[v][1] for v in views])
    truth = np.array([rig[v].center for v in views])
    s, R, t = similarity(centres, truth)
    row["cam_center_err"] = float(np.linalg.norm(s * centres @ R.T + t - truth, axis=1).mean())
    return row, (s, R, t)


def registered_poses(
    model, view_of_name: dict[str, int]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{view: (R, t) cam_from_world} of the registered images of a COLMAP model."""
    est = {}
    for image_id in model.reg_image_ids() if model is not None else []:
        img = model.images[image_id]
        pose = img.cam_from_world()
        est[view_of_name[img.name]] = (
            np.asarray(pose.rotation.matrix()),
            np.asarray(pose.translation),
        )
    return est


def evaluate_mapping(truth: SceneTruth, model, view_of_name: dict[str, int]) -> dict[str, float]:
    """Every metric of an sfm model: pose metrics against the rig, then the ground-truth
    accuracy of its points after the similarity alignment, its tracks and reprojection."""
    row, sim = pose_metrics(registered_poses(model, view_of_name), truth.cams)
    X = model_points(model)
    if sim is None:
        X = X[:0]
    else:
        s, R, t = sim
        X = s * X @ R.T + t
    row |= point_metrics(X, truth.surface, truth.track_points(3))
    row["points"] = 0 if model is None else model.num_points3D()
    row |= track_metrics(model)
    row["mean_reproj_px"] = (
        model.compute_mean_reprojection_error()
        if model is not None and model.num_points3D()
        else math.nan
    )
    return row
