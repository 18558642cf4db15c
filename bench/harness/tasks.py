"""The task registry: for each reconstruction task, what its selection may see, how it
reconstructs from the selected keypoints and verified matches, how its model is scored
and which metrics its rows must hold. Adding a task is one `register` call here; what the
report shows of it (its headline metrics in the paired tables, the figures, the page and
the transfer table; which are lower-better; whether the stock-COLMAP exclusion rule holds)
is declared on its `Task` and read from the results folder's recorded vocabulary.

* `tri`: triangulation with the rig's known poses, scored against the ground-truth
  surface (`bench.evaluation.metrics`).
* `sfm`: incremental mapping with unknown poses, scored by pose accuracy
  (`bench.evaluation.poses`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.backend.matching import BackendConfig, PairMatches
from bench.backend.reconstruction import (
    Reconstruction,
    known_pose_model,
    known_pose_task,
    mapping_task,
)
from bench.camera import Camera
from bench.evaluation.metrics import evaluate_known_pose
from bench.evaluation.poses import evaluate_mapping
from bench.evaluation.truth import SceneTruth
from bench.frontend.geometry import IMAGES, RIG
from bench.vocabulary import PROTOCOLS, Task, declare_task


@dataclass(frozen=True)
class Matched:
    """What a task reconstructs from: the views and the selection's verified matches."""

    image_dir: Path
    cams: list[Camera]
    names: list[str]
    xy: list[np.ndarray]
    pairs: list[PairMatches]


Reconstruct = Callable[[Matched, BackendConfig, str], Reconstruction]
Evaluate = Callable[[SceneTruth, object, list[str], str], dict[str, float]]
"""(truth, the exported model or None, the view names, the track protocol) -> metrics."""


@dataclass(frozen=True)
class TaskRunner:
    spec: Task
    reconstruct: Reconstruct
    evaluate: Evaluate
    record: Callable[[Matched], object] | None = None
    """The model exported when the task reconstructs nothing (None: nothing is)."""


RUNNERS: dict[str, TaskRunner] = {}


def register(runner: TaskRunner) -> None:
    declare_task(runner.spec)
    RUNNERS[runner.spec.name] = runner


def view_of_name(names: list[str]) -> dict[str, int]:
    return {name: k for k, name in enumerate(names)}


TRI_COLUMNS = (
    "rmse",
    "acc_completeness_pct",
    "completeness_vs_oracle_pct",
    "accuracy_pct",
    "inlier_pct",
    "coverage_pct",
    "runtime_proxy",
    "wall_ms",
    "median_error",
    "match_precision_pct",
    "acc_completeness_pct_0.02",
    "acc_completeness_pct_0.05",
    "acc_completeness_pct_0.20",
    "accuracy_pct_0.02",
    "accuracy_pct_0.05",
    "accuracy_pct_0.20",
    "points",
    "reconstructable",
    "mean_track_length",
    "mean_tri_angle_deg",
    "runtime_scoring",
    "runtime_matching",
    "runtime_robust",
    "task_ms",
)
SFM_COLUMNS = (
    "maa",
    "keypoints_per_view",
    "registered_views",
    "median_pose_err_deg",
    "cam_center_err",
    "points",
    "accuracy_pct",
    "rmse",
    "median_error",
    "mean_track_length",
    "mean_reproj_px",
    "task_ms",
    "wall_ms",
)

register(
    TaskRunner(
        Task(
            "tri",
            RIG,
            needs=("points", "acc_completeness_pct"),
            columns=TRI_COLUMNS,
            doc="known poses, scored against the ground-truth surface",
            headline=("acc_completeness_pct", "accuracy_pct", "rmse", "median_error"),
            lower_better=("rmse", "median_error", "runtime_proxy", "wall_ms", "task_ms"),
            summary=("acc_completeness_pct", "accuracy_pct", "rmse", "points", "coverage_pct"),
            titles={
                "acc_completeness_pct": "Acc. completeness % (e < 0.10)",
                "completeness_vs_oracle_pct": "Completeness, % of the oracle's",
                "accuracy_pct": "Accuracy % (points with e < 0.10)",
                "rmse": "RMSE (scene units)",
                "median_error": "Median error (scene units)",
                "inlier_pct": "Inlier %",
                "coverage_pct": "Coverage %",
                "runtime_proxy": "Runtime proxy (k ops)",
            },
        ),
        reconstruct=lambda m, cfg, protocol: known_pose_task(
            m.image_dir, m.cams, m.names, m.xy, m.pairs, cfg, protocol
        ),
        evaluate=lambda truth, model, names, protocol: evaluate_known_pose(
            truth, model, PROTOCOLS[protocol]
        ),
        record=lambda m: known_pose_model(m.cams, m.names, m.xy),
    )
)
register(
    TaskRunner(
        Task(
            "sfm",
            IMAGES,
            needs=("maa", "registered_views"),
            columns=SFM_COLUMNS,
            peers=True,
            doc="unknown poses, scored by pose mAA",
            headline=("maa",),
            lower_better=(
                "rmse",
                "median_error",
                "median_pose_err_deg",
                "cam_center_err",
                "mean_reproj_px",
                "wall_ms",
                "task_ms",
            ),
            summary=("maa", "registered_views"),
            titles={"maa": "SfM pose mAA (1-10 deg), unknown poses"},
            exclusion_reference=True,
        ),
        reconstruct=lambda m, cfg, protocol: mapping_task(
            m.image_dir, m.cams, m.names, m.xy, m.pairs, cfg, protocol
        ),
        evaluate=lambda truth, model, names, protocol: evaluate_mapping(
            truth, model, view_of_name(names)
        ),
    )
)
