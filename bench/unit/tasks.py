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
* `pairs`: no reconstruction; the relative pose of every pair, as the verification of the
  selection's matches estimated it (stored with the prediction), scored by relative-pose
  AUC and mAA (`bench.evaluation.relative`). The track protocol does not apply: one row
  per unit, its protocol `none` (`Task.tracks`).

The next-views task (`nbv`) is registered where it is run, `bench.unit.nbv`: only the
view choosers run it (`TaskRunner.kinds`), each unit whole, on the scene's planned path
(`TaskRunner.rig`), and it is not in the default grid (`TaskRunner.default`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bench.backend.matching import BackendConfig, PairMatches
from bench.backend.reconstruction import (
    Reconstruction,
    known_pose_model,
    known_pose_task,
    mapping_task,
)
from bench.camera import Camera
from bench.evaluation.metrics import evaluate_known_pose, model_points, point_error
from bench.evaluation.poses import evaluate_mapping
from bench.evaluation.relative import RelativePoses, evaluate_pairs
from bench.evaluation.truth import SceneTruth
from bench.files import atomic_path
from bench.frontend.geometry import IMAGES, RIG
from bench.results import POINT_ERRORS
from bench.vocabulary import PROTOCOLS, Task, declare_task

if TYPE_CHECKING:  # (RunConfig imports the declaring modules, this one among them)
    from bench.render.config import RenderConfig
    from bench.unit.config import RunConfig


@dataclass(frozen=True)
class Matched:
    """What a task reconstructs from: the views and the selection's verified matches."""

    cams: list[Camera]
    names: list[str]
    xy: list[np.ndarray]
    pairs: list[PairMatches]


Reconstruct = Callable[[Matched, BackendConfig, str], Reconstruction]
Evaluate = Callable[[SceneTruth, object, list[str], str, RelativePoses], dict[str, float]]
"""(truth, the exported model or None, the view names, the track protocol, the stored
relative poses of the verified pairs) -> metrics."""


@dataclass(frozen=True)
class TaskRunner:
    spec: Task
    reconstruct: Reconstruct | None = None
    """None for a task whose methods' kind runs its units whole (`kinds`: the nbv task)."""
    evaluate: Evaluate | None = None
    record: Callable[[Matched], object] | None = None
    """The model exported when the task reconstructs nothing (None: nothing is)."""
    maps: bool = False
    """Whether it runs COLMAP's incremental mapper: a stock-COLMAP peer maps its own
    database for it (`bench.backend.peers.run_peer`); a peer gives a task that does not
    its keypoints and verified pairs (`Matched`), as a policy does."""
    keep: Callable[[object, SceneTruth, Path], None] | None = None
    """What the scoring writes beside a job's exported model (the model, the truth, the
    model's folder); None: nothing."""
    kinds: tuple[str, ...] = ()
    """The kinds of method that run it (`bench.vocabulary.KINDS`); empty: every kind that
    no task claims this way (`bench.harness.grid.BenchConfig.jobs`)."""
    rig: Callable[[RunConfig], RenderConfig] | None = None
    """The render settings of the entry its units read on a rendered scene (None: the
    run's); a grid runs such a task alone."""
    default: bool = True
    """Whether `bench run` runs it without `--tasks`."""
    settings: tuple[str, ...] = ()
    """The sections of the run's settings its predicted rows read beyond every task's
    (`bench.unit.config.PREDICTION`): the nbv task's `nbv`."""


TASK_RUNNERS: dict[str, TaskRunner] = {}
"""Every task's runner, by name (as `bench.unit.methods.KIND_RUNNERS` holds every kind's)."""


def register(runner: TaskRunner) -> None:
    declare_task(runner.spec)
    TASK_RUNNERS[runner.spec.name] = runner


def view_of_name(names: list[str]) -> dict[str, int]:
    return {name: k for k, name in enumerate(names)}


def write_point_errors(model, truth: SceneTruth, out: Path) -> None:
    """Each point's distance to the ground-truth surface (`point3D_id,error`), where there
    are points and a surface."""
    ids = list(model.points3D) if model is not None else []
    if not ids or truth.surface is None:
        return
    errors = point_error(model_points(model), truth.surface)
    with atomic_path(out / POINT_ERRORS) as tmp:
        np.savetxt(
            tmp,
            np.c_[ids, errors],
            fmt=["%d", "%.6g"],
            delimiter=",",
            header="point3D_id,error",
            comments="",
        )


TRI_METRICS = (
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
SFM_METRICS = (
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
            metrics=TRI_METRICS,
            doc="known poses, scored against the ground-truth surface",
            headline=("acc_completeness_pct", "accuracy_pct", "rmse", "median_error"),
            summary=("acc_completeness_pct", "accuracy_pct", "rmse", "points", "coverage_pct"),
            drawn=(
                "acc_completeness_pct",
                "completeness_vs_oracle_pct",
                "accuracy_pct",
                "rmse",
                "median_error",
                "inlier_pct",
                "coverage_pct",
                "runtime_proxy",
            ),
        ),
        reconstruct=lambda m, cfg, protocol: known_pose_task(
            m.cams, m.names, m.xy, m.pairs, cfg, protocol
        ),
        evaluate=lambda truth, model, names, protocol, poses: evaluate_known_pose(
            truth, model, PROTOCOLS[protocol]
        ),
        record=lambda m: known_pose_model(m.cams, m.names, m.xy),
        keep=write_point_errors,
    )
)
register(
    TaskRunner(
        Task(
            "sfm",
            IMAGES,
            needs=("maa", "registered_views"),
            metrics=SFM_METRICS,
            peers=True,
            doc="unknown poses, scored by pose mAA",
            headline=("maa",),
            summary=("maa", "registered_views"),
            drawn=("maa",),
            exclusion_reference=True,
        ),
        reconstruct=lambda m, cfg, protocol: mapping_task(
            m.cams, m.names, m.xy, m.pairs, cfg, protocol
        ),
        evaluate=lambda truth, model, names, protocol, poses: evaluate_mapping(
            truth, model, view_of_name(names)
        ),
        maps=True,
    )
)


def relative_poses(m: Matched, cfg: BackendConfig, protocol: str) -> Reconstruction:
    """Task `pairs`: nothing to reconstruct, the verification estimated each pair's
    relative pose; a unit without any is failed (its rows still scored: every pair missing)."""
    if sum(len(p.verified) for p in m.pairs) == 0:
        return Reconstruction(None, "no pair of views has verified matches", 0.0)
    if all(p.pose is None for p in m.pairs):
        return Reconstruction(None, "no pair of views has a relative pose", 0.0)
    return Reconstruction(None, None, 0.0)


PAIRS_METRICS = (
    "auc_5",
    "auc_10",
    "auc_20",
    "maa_pairs",
    "median_pose_err_deg",
    "pairs_scored",
    "pairs_estimated",
    "task_ms",
    "wall_ms",
)

register(
    TaskRunner(
        Task(
            "pairs",
            IMAGES,
            needs=("auc_10", "maa_pairs", "pairs_scored"),
            metrics=PAIRS_METRICS,
            peers=True,
            doc="relative poses of the verified pairs, scored by pose AUC",
            headline=("auc_10", "auc_5", "auc_20", "maa_pairs"),
            summary=("auc_10", "maa_pairs", "pairs_estimated"),
            drawn=("auc_10", "auc_5", "auc_20", "maa_pairs"),
            tracks=False,
        ),
        reconstruct=relative_poses,
        evaluate=lambda truth, model, names, protocol, poses: evaluate_pairs(truth, poses),
    )
)
