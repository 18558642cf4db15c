"""Relative-pose accuracy of the `pairs` task: the two-view poses a selection's verified
matches give, against the rig (the render entry's ground-truth poses).

Which pairs are scored is decided by the ground truth alone, the same for every method of
a scene and seed: the covisible pairs (`SceneTruth.covisible_pairs`), those that share at
least `MIN_SHARED` ground-truth points (tracks); on a dataset without per-pixel truth,
those whose model observes at least as many common points, and where the model has no
points, those whose viewing directions are within 60 degrees and whose frustums overlap
(the Image Matching Benchmark scores covisible pairs only: a pair that shares no surface
cannot have a relative pose from matches). `pairs_rule` says which rule a row used.

The estimate of pair (i, j) is cam_j_from_cam_i = (R, t) as COLMAP's calibrated two-view
geometry estimated it from the pair's verified matches with the known intrinsics (the
verification's own pose, `bench.backend.matching`). Its error against the rig's
(R_j R_i^T, t_j - R_j R_i^T t_i), as SuperGlue's and glue-factory's relative-pose
evaluations compute it (`compute_pose_error` of magicleap/SuperGluePretrainedNetwork,
models/utils.py; `relative_pose_error` of cvg/glue-factory, gluefactory/geometry/epipolar.py):

* rotation error: the angle of R_est^T R_gt;
* translation-direction error: the angle between t_est and t_gt, sign-free (min(a, 180 - a):
  an essential matrix fixes the direction of the translation up to its sign);
* pose error: the larger of the two. A pair without an estimate (no verified matches, no
  pose, or a non-finite one) has pose error 180 degrees.

Errors are rounded to 1e-6 degrees, as in `bench.evaluation.poses`. Then:

* `auc_5`, `auc_10`, `auc_20`: the area under the recall curve of the pose errors (the
  share of pairs with error at most e, linear between the sorted errors, from (0, 0)) up to
  5, 10 and 20 degrees, divided by the threshold: SuperGlue's `pose_auc` (Sarlin et al.,
  CVPR 2020, models/utils.py), LightGlue's and glue-factory's `cal_error_auc`
  (cvg/glue-factory, gluefactory/utils/tools.py; without its rounding to 4 decimals);
* `maa_pairs`: the mean over the thresholds 1, 2, ..., 10 degrees of the share of pairs
  whose pose error is below the threshold: the Image Matching Benchmark's stereo-track mAA
  (Jin et al., IJCV 2021), as `bench.evaluation.poses` computes it over the mapper's poses;
* `median_pose_err_deg`: the median pose error over the scored pairs (missing ones at 180);
* `pairs_scored`, `pairs_estimated`: the pairs scored, and those of them with an estimate.

A scene and seed without a scored pair scores 0, never NaN (its median is NaN).
"""

from __future__ import annotations

import math

import numpy as np

from bench.camera import Camera
from bench.evaluation.poses import MAA_THRESHOLDS_DEG, _angle_deg
from bench.evaluation.truth import SceneTruth
from bench.vocabulary import FRACTION, Metric, declare_metric

MIN_SHARED = 15
"""The fewest ground-truth points two views must share for their pair to be scored."""
AUC_THRESHOLDS_DEG = (5, 10, 20)
MISSING_DEG = 180.0
"""The pose error of a pair without an estimate."""

for _metric in (
    Metric("auc_5", FRACTION, title="Relative-pose AUC @5 deg", failure=0.0),
    Metric("auc_10", FRACTION, title="Relative-pose AUC @10 deg, unknown poses", failure=0.0),
    Metric("auc_20", FRACTION, title="Relative-pose AUC @20 deg", failure=0.0),
    Metric("maa_pairs", FRACTION, title="Relative-pose mAA (1-10 deg)", failure=0.0),
    Metric("pairs_scored"),
    Metric("pairs_estimated", failure=0.0),
):
    declare_metric(_metric)

RelativePoses = dict[tuple[int, int], np.ndarray]
"""{(i, j), i < j: [R | t] (3, 4) of view j's camera from view i's}."""


def relative_pose_error(est: np.ndarray, cam_i: Camera, cam_j: Camera) -> float:
    """The pose error in degrees (module docstring) of an estimated [R | t] of j from i."""
    R, t = est[:, :3], est[:, 3]
    Rg = cam_j.R @ cam_i.R.T
    tg = cam_j.t - Rg @ cam_i.t
    rot = _angle_deg((np.trace(R.T @ Rg) - 1) / 2)
    tra = _angle_deg(abs(float(t @ tg)) / max(np.linalg.norm(t) * np.linalg.norm(tg), 1e-15))
    return max(rot, tra)


def pose_auc(errors, thresholds) -> list[float]:
    """The normalised area under the recall curve of `errors` up to each threshold
    (module docstring); 0 for no errors."""
    e = np.sort(np.asarray(errors, np.float64))
    if not len(e):
        return [0.0] * len(thresholds)
    recall = np.arange(len(e) + 1) / len(e)
    e = np.r_[0.0, e]
    out = []
    for th in thresholds:
        k = int(np.searchsorted(e, th))  # the points of the curve below the threshold
        x, r = np.r_[e[:k], th], np.r_[recall[:k], recall[k - 1]]
        out.append(float(np.sum((r[1:] + r[:-1]) / 2 * np.diff(x)) / th))
    return out


def pair_metrics(errors, estimated: int) -> dict[str, float]:
    """The pairs task's metrics from the pose errors of the scored pairs (module
    docstring); `estimated`: how many of them have an estimate."""
    err = np.round(np.asarray(errors, np.float64), 6)
    aucs = pose_auc(err, AUC_THRESHOLDS_DEG)
    row = {f"auc_{th}": a for th, a in zip(AUC_THRESHOLDS_DEG, aucs)}
    row["maa_pairs"] = (
        float(np.mean([np.mean(err < th) for th in MAA_THRESHOLDS_DEG])) if len(err) else 0.0
    )
    row["median_pose_err_deg"] = float(np.median(err)) if len(err) else math.nan
    row["pairs_scored"] = len(err)
    row["pairs_estimated"] = estimated
    return row


def evaluate_pairs(truth: SceneTruth, poses: RelativePoses) -> dict[str, float]:
    """Every metric of the pairs task from a unit's stored relative poses."""
    poses = {p: e for p, e in poses.items() if np.isfinite(e).all()}
    pairs, rule = truth.covisible_pairs(MIN_SHARED)
    errors = [
        relative_pose_error(poses[p], truth.cams[p[0]], truth.cams[p[1]])
        if p in poses
        else MISSING_DEG
        for p in pairs
    ]
    return pair_metrics(errors, sum(p in poses for p in pairs)) | {"pairs_rule": rule}
