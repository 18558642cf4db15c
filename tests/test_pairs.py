"""The `pairs` task: relative-pose errors, AUC and mAA on hand-made cases with known
answers, the pairs the ground truth scores, and one unit end to end (a policy and a peer),
scored again from its stored prediction alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.camera import look_at
from bench.evaluation.layers import read_layers
from bench.evaluation.relative import (
    MISSING_DEG,
    evaluate_pairs,
    pair_metrics,
    pose_auc,
    relative_pose_error,
)
from bench.evaluation.truth import SceneTruth
from bench.frontend.geometry import IMAGES
from bench.frontend.stage import front_end
from bench.frontend.views import load_views
from bench.harness.execute import Work, compute_unit
from bench.harness.keys import unit_keys
from bench.results import Workspace
from bench.unit.config import RunConfig
from bench.unit.evaluate import evaluate
from bench.unit.methods import runner
from bench.unit.predict import LoadedScene
from bench.vocabulary import Job, Unit, Vocabulary


def rotation(axis, deg: float) -> np.ndarray:
    """Rodrigues: the rotation by `deg` degrees about `axis`."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = math.radians(deg)
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K


CAMS = [look_at((x, -8.0, 1.0), (0.0, 0.0, 1.0), width=640, height=480) for x in (-1, 0, 1.5)]


def truth_pose(i: int, j: int) -> np.ndarray:
    R = CAMS[j].R @ CAMS[i].R.T
    t = CAMS[j].t - R @ CAMS[i].t
    return np.c_[R, t / np.linalg.norm(t)]


def test_the_pose_error_is_sign_and_scale_free_in_the_translation():
    est = truth_pose(0, 1)
    assert relative_pose_error(est, CAMS[0], CAMS[1]) == pytest.approx(0, abs=1e-5)
    flipped = np.c_[est[:, :3], -3 * est[:, 3]]  # t and -t: the same direction, sign-free
    assert relative_pose_error(flipped, CAMS[0], CAMS[1]) == pytest.approx(0, abs=1e-5)


def test_the_pose_error_is_the_larger_of_rotation_and_translation_direction():
    est = truth_pose(0, 2)
    turned = np.c_[rotation((0, 1, 0.3), 3.0) @ est[:, :3], est[:, 3]]
    assert relative_pose_error(turned, CAMS[0], CAMS[2]) == pytest.approx(3.0, abs=1e-6)
    across = np.cross(est[:, 3], (0, 1, 0))  # an axis perpendicular to t
    t = rotation(across, 7.0) @ est[:, 3]  # the direction 7 degrees off, rotation exact
    assert relative_pose_error(np.c_[est[:, :3], t], CAMS[0], CAMS[2]) == pytest.approx(7.0)
    both = np.c_[turned[:, :3], t]
    assert relative_pose_error(both, CAMS[0], CAMS[2]) == pytest.approx(7.0)
    # 170 degrees off in direction is 10 degrees off, sign-free
    t = rotation(across, 170.0) @ est[:, 3]
    assert relative_pose_error(np.c_[est[:, :3], t], CAMS[0], CAMS[2]) == pytest.approx(10.0)


def test_auc_and_maa_of_five_known_errors():
    """Errors 1, 3, 7, 12 degrees and one missing pair (180): the recall curve through
    (0, 0), (1, .2), (3, .4), (7, .6), (12, .8), integrated by hand."""
    errors = [7.0, 1.0, MISSING_DEG, 12.0, 3.0]
    assert pose_auc(errors, (5, 10, 20)) == pytest.approx([1.5 / 5, 4.5 / 10, 12.6 / 20])
    row = pair_metrics(errors, estimated=4)
    assert row["auc_5"] == pytest.approx(0.3)
    assert row["auc_10"] == pytest.approx(0.45)
    assert row["auc_20"] == pytest.approx(0.63)
    # below 1..10 degrees: 0, 1, 1, 2, 2, 2, 2, 3, 3, 3 of the 5 pairs (an error equal to
    # the threshold is not below it)
    assert row["maa_pairs"] == pytest.approx(19 / 50)
    assert row["median_pose_err_deg"] == 7.0
    assert (row["pairs_scored"], row["pairs_estimated"]) == (5, 4)


def test_perfect_missing_and_empty():
    assert pose_auc([0.0, 0.0], (5, 10, 20)) == [1.0, 1.0, 1.0]
    every_missing = pair_metrics([MISSING_DEG] * 3, estimated=0)
    assert every_missing["auc_10"] == every_missing["maa_pairs"] == 0.0
    assert every_missing["median_pose_err_deg"] == MISSING_DEG
    empty = pair_metrics([], estimated=0)
    assert empty["auc_5"] == empty["maa_pairs"] == 0.0 and math.isnan(empty["median_pose_err_deg"])


def toy_truth(shared: dict[tuple[int, int], int]) -> SceneTruth:
    """Three views whose candidates share the given numbers of ground-truth tracks."""
    labels: list[list[int]] = [[100 + v] for v in range(3)]  # a track of one view each
    for n, ((i, j), k) in enumerate(shared.items()):
        for m in range(k):
            labels[i].append(1000 * (n + 1) + m)
            labels[j].append(1000 * (n + 1) + m)
    track = [np.array(x) for x in labels]
    return SceneTruth(None, CAMS, None, None, [np.zeros((0, 2))] * 3, track, np.zeros(0))


def test_the_ground_truth_alone_decides_which_pairs_are_scored():
    truth = toy_truth({(0, 1): 20, (1, 2): 14, (0, 2): 15})
    assert truth.shared_pairs(15) == [(0, 1), (0, 2)]
    poses = {(0, 1): truth_pose(0, 1), (1, 2): truth_pose(1, 2)}  # (1, 2) is not scored
    row = evaluate_pairs(truth, poses)
    assert (row["pairs_scored"], row["pairs_estimated"]) == (2, 1)
    assert row["auc_5"] == pytest.approx(0.5)  # one exact pair, one missing
    assert row["median_pose_err_deg"] == pytest.approx(90.0)  # of 0 and 180
    # a non-finite estimate is no estimate
    bad = evaluate_pairs(truth, {(0, 1): np.full((3, 4), np.nan)})
    assert bad["pairs_estimated"] == 0 and bad["auc_20"] == 0.0
    assert row["pairs_rule"] == "ground-truth tracks >= 15"


def _posed(cams, seen=None) -> SceneTruth:
    """A dataset's truth with poses alone (and the points its model observes)."""
    empty = [np.zeros((0, 2))] * len(cams)
    return SceneTruth(None, cams, None, None, empty, None, None, "poses", seen)


def test_a_dataset_scores_its_covisible_pairs_only():
    """Without per-pixel truth: the pairs whose model points are shared (15 at least), or,
    without model points, whose viewing directions are within 60 degrees and whose
    frustums overlap: on a ring of eight views around an object, each view's neighbours
    (45 degrees apart), not the views across the ring (the pairs of a 47-view ring that
    share no surface pinned every method at 180 degrees)."""
    ring = [
        look_at((6 * math.cos(a), 6 * math.sin(a), 1.0), (0, 0, 1.0), width=640, height=480)
        for a in np.radians(np.arange(0, 360, 45))
    ]
    pairs, rule = _posed(ring).covisible_pairs(15)
    assert rule.startswith("viewing directions within 60 deg")
    assert pairs == sorted({tuple(sorted((i, (i + 1) % 8))) for i in range(8)})
    path = [look_at((x, -6.0, 1.0), (x, 0.0, 1.0), width=640, height=480) for x in (0, 1, 2)]
    assert _posed(path).covisible_pairs(15)[0] == [(0, 1), (0, 2), (1, 2)]  # parallel axes
    apart = [look_at((0, -6, 1.0), (0, 0, 1.0)), look_at((30, -6, 1.0), (40, 0, 1.0))]
    assert _posed(apart).covisible_pairs(15)[0] == []  # 40 degrees apart, nothing shared
    seen = [np.arange(20), np.arange(5, 40), np.arange(30, 44)]  # 15 and 10 shared
    pairs, rule = _posed(ring[:3], seen).covisible_pairs(15)
    assert (pairs, rule) == ([(0, 1)], "model tracks >= 15")
    poses = {(0, 1): np.c_[np.eye(3), [1.0, 0, 0]], (1, 2): np.c_[np.eye(3), [1.0, 0, 0]]}
    row = evaluate_pairs(_posed(ring[:3], seen), poses)
    assert (row["pairs_scored"], row["pairs_estimated"]) == (1, 1)


def test_the_task_is_declared_for_the_report():
    vocab = Vocabulary.current()
    pairs = vocab.tasks["pairs"]
    assert pairs.grant == IMAGES and pairs.peers and not pairs.exclusion_reference
    assert "pairs_auc_10" in vocab.first_headline()
    assert "pairs_median_pose_err_deg" in vocab.lower_better()
    assert vocab.range_of("auc_20") == (0.0, 1.0) and vocab.range_of("maa_pairs") == (0.0, 1.0)


@pytest.mark.parametrize("method, budget", [("texture", 128), ("colmap-b", 128)])
def test_one_unit_end_to_end_and_scored_again_from_its_prediction(
    medium_entry, frontend_cache, tmp_path, method, budget
):
    """A policy's and a peer's pairs rows: the relative poses are stored with the
    prediction (nothing is mapped or exported), and scoring them again from it alone gives
    the same row."""
    entry = medium_entry("table")
    cfg = RunConfig()
    fe = front_end(entry, cfg.detector, cfg.signals, frontend_cache, IMAGES)
    posed = [v.camera for v in load_views(entry)]  # the evaluation's: the rig's poses
    truth = SceneTruth.build(posed, read_layers(entry), fe.pools)
    scene, ws = LoadedScene(entry, {IMAGES: fe}, truth), Workspace(tmp_path / "r", tmp_path)
    unit, jobs = Unit("table", 0, method, budget), [Job("pairs", "multiview")]
    (row,) = compute_unit(scene, unit, Work(tuple(jobs)), cfg, ws)
    assert row["status"] == "ok", row["failure"]
    assert 0 < row["pairs_estimated"] <= row["pairs_scored"] <= 15
    assert row["pairs_scored"] == len(truth.shared_pairs(15))
    for m in ("auc_5", "auc_10", "auc_20", "maa_pairs"):
        assert 0 <= row[m] <= 1, m
    assert row["auc_5"] <= row["auc_10"] <= row["auc_20"] and row["auc_20"] > 0
    assert not ws.model_dir(unit, jobs[0]).exists()  # nothing reconstructed, nothing exported
    keys = unit_keys(cfg, method)
    (again,) = evaluate(scene, unit, jobs, cfg, ws, runner(method).read, keys)
    for m in ("auc_5", "auc_10", "auc_20", "maa_pairs", "median_pose_err_deg", "pairs_estimated"):
        assert again[m] == row[m], m
