"""One run end to end on a small real render: a complete row, and an export that matches it."""

from __future__ import annotations

import math

import pycolmap
import pytest

from bench.evaluate import SceneTruth
from bench.frontend import front_end
from bench.groundtruth import load_ground_truth
from bench.pipeline import RunConfig, run_one

METRICS = [
    "rmse",
    "median_error",
    "acc_completeness_pct",
    "acc_completeness_pct_0.02",
    "acc_completeness_pct_0.05",
    "acc_completeness_pct_0.20",
    "inlier_pct",
    "match_precision_pct",
    "coverage_pct",
    "mean_track_length",
    "mean_tri_angle_deg",
    "runtime_proxy",
    "runtime_scoring",
    "runtime_matching",
    "runtime_robust",
    "wall_ms",
    "detect_ms",
    "signals_ms",
    "select_ms",
    "match_ms",
    "verify_ms",
    "triangulate_ms",
    "evaluate_ms",
    "render_s_per_view",
]


@pytest.fixture(scope="module")
def table_run(medium_entry, tmp_path_factory):
    entry = medium_entry("table")
    cfg = RunConfig()
    fe = front_end(entry, cfg.detector, cfg.signals, tmp_path_factory.mktemp("fe"))
    truth = SceneTruth.build([v.camera for v in fe.views], load_ground_truth(entry), fe.pools)
    out = tmp_path_factory.mktemp("models")

    def run(policy: str, budget: int = 128):
        return run_one(
            entry, fe, truth, "table", 0, policy, budget, cfg, out / f"{policy}-b{budget}"
        ), out / f"{policy}-b{budget}"

    run.pool_size = sum(len(p) for p in fe.pools)
    return run


@pytest.mark.parametrize("policy", ["all", "adaptive"])
def test_one_run_gives_a_complete_row(table_run, policy):
    row, model_dir = table_run(policy)
    assert row["status"] == "ok", row["failure"]
    for k in METRICS:
        assert isinstance(row[k], float | int) and math.isfinite(row[k]), k
    assert row["points"] > 0 and row["reconstructable"] > 0
    model = pycolmap.Reconstruction(str(model_dir))
    assert model.num_points3D() == row["points"]
    assert model.num_images() == 6
    selected = sum(img.num_points2D() for img in model.images.values())
    assert selected == (6 * 128 if policy == "adaptive" else table_run.pool_size)


def test_budgeted_images_txt_lists_every_selected_keypoint(table_run):
    _, model_dir = table_run("texture", 64)
    model = pycolmap.Reconstruction(str(model_dir))
    assert [img.num_points2D() for img in model.images.values()] == [64] * 6
