"""The next-views task: the view choosers on hand-made captures of known answer, their
contract and firewall, and a small real run (rendered path, then the same path as a
dataset) whose rows, Table 3 and oracle bound are checked."""

from __future__ import annotations

import importlib
import json
import shutil
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from bench import BenchError
from bench.acquisition import choosers
from bench.acquisition.choosers import (
    CHOOSERS,
    CandidatePose,
    CapturedView,
    ChooserFailed,
    ChooserInput,
    OwnModel,
    choose,
    chooser,
    chooser_rng,
)
from bench.backend.matching import PairMatches
from bench.binding import read_vocabulary
from bench.camera import look_at
from bench.evaluation.export import export_dataset
from bench.frontend.features import Candidates
from bench.frontend.signals import SIGNALS, Signals
from bench.frontend.views import View
from bench.harness.grid import BenchConfig
from bench.render.entry import render_scene
from bench.report.transfer import transfer
from bench.runs import read_runs
from bench.unit.config import NbvConfig, RunConfig
from bench.vocabulary import METHODS
from tests.conftest import MEDIUM, bench_run

TARGET = (0.0, 0.0, 1.0)


def _captured(cam, index: int, xy=None) -> CapturedView:
    xy = np.zeros((0, 2)) if xy is None else xy
    n = len(xy)
    pool = Candidates(xy, np.full(n, 4.0), np.zeros(n), np.ones(n), np.zeros((n, 128), np.float32))
    view = View(index, f"view_{index:02d}.png", np.zeros((4, 4, 3), np.uint8), cam)
    return CapturedView(view, pool, Signals(*(np.zeros(n) for _ in SIGNALS)), np.arange(n))


def _row_capture(xs, target=TARGET):
    """Cameras at x in `xs` on the line y = -8, looking at `target`."""
    return [look_at((x, -8.0, 1.0), target) for x in xs]


def _input(captured, candidates, model=None, pairs=()):
    empty = OwnModel(np.zeros((0, 3)), ())
    return ChooserInput(tuple(captured), tuple(pairs), model or empty, tuple(candidates))


def test_farthest_view_picks_the_candidate_farthest_from_every_captured_view():
    captured = [_captured(c, 2 * k) for k, c in enumerate(_row_capture([0.0, 1.0, 2.0]))]
    near, far, between = _row_capture([0.5, 9.0, 3.0])
    inp = _input(
        captured, [CandidatePose(1, near), CandidatePose(5, far), CandidatePose(6, between)]
    )
    assert choose("farthest-view", inp, chooser_rng(0, "farthest-view", 0)) == 1


def test_gap_view_splits_the_longest_gap_along_the_path_at_its_middle():
    # captured at path positions 0, 4 and 10 (x = 0, 1, 5): the gap 4-10 is the longest
    xs = {0: 0.0, 1: 0.25, 2: 0.5, 3: 0.75, 4: 1.0, 5: 1.5, 6: 2.5, 7: 3.0, 8: 3.5, 9: 4.5, 10: 5.0}
    cams = dict(zip(xs, _row_capture(list(xs.values()))))
    captured = [_captured(cams[i], i) for i in (0, 4, 10)]
    offered = [CandidatePose(i, cams[i]) for i in xs if i not in (0, 4, 10)]
    picked = offered[choose("gap-view", _input(captured, offered), chooser_rng(0, "gap-view", 0))]
    assert picked.index == 7  # x = 3.0, the middle of x 1..5


def _weak_capture(xs=(-0.3, 0.0, 0.3), model=True):
    """Cameras at x in `xs`, 40 points near the origin seen and matched in all of them,
    triangulated from all (`model`; else no point: untriangulated matched tracks)."""
    cams = _row_capture(list(xs))
    rng = np.random.default_rng(0)
    X = np.c_[rng.uniform(-1, 1, 40), rng.uniform(-0.5, 0.5, 40), rng.uniform(0.5, 1.5, 40)]
    captured = [_captured(c, 4 * k, c.project(X)[0]) for k, c in enumerate(cams)]
    tracks = tuple(np.array([(v, p) for v in range(len(xs))]) for p in range(len(X)))
    same = np.c_[np.arange(40), np.arange(40)]
    pairs = [
        PairMatches(i, j, same, same, "CALIBRATED")
        for i in range(len(xs))
        for j in range(i + 1, len(xs))
    ]
    own = OwnModel(X, tracks) if model else OwnModel(np.zeros((0, 3)), ())
    return captured, own, pairs, X


CLOSE = look_at((0.5, -8.0, 1.0), TARGET)  # sees the points, at a small angle
AWAY = look_at((30.0, -8.0, 1.0), (30.0, 0.0, 1.0))  # the farthest; sees none of them
WIDE = look_at((3.0, -8.0, 1.0), TARGET)  # sees them, at over 10 degrees


def test_weak_triangulation_picks_the_candidate_giving_weak_points_the_largest_angle():
    captured, model, pairs, _ = _weak_capture()  # three views 4.3 degrees apart: weak
    offered = [CandidatePose(1, CLOSE), CandidatePose(5, AWAY), CandidatePose(9, WIDE)]
    inp = _input(captured, offered, model, pairs)
    weak = choosers.weak_points(inp)
    assert weak.point.all() and len(weak.X) == 40 and (weak.angle < 5).all()
    a = choosers.expected_angles(weak.X, weak.seen, inp)
    assert np.isnan(a[1]).all() and (weak.angle < a[0]).all() and (a[0] < 10).all()
    assert (a[2] > 10).all()
    gains = choosers.angle_gains(weak, inp).sum(1)
    assert gains[1] == 0 < gains[0] < gains[2]
    assert choose("weak-triangulation", inp, chooser_rng(0, "weak-triangulation", 0)) == 2
    assert choose("farthest-view", inp, chooser_rng(0, "farthest-view", 0)) == 1


def test_a_matched_track_one_view_short_of_a_point_counts_where_its_rays_meet():
    captured, model, pairs, X = _weak_capture((-0.3, 0.3), model=False)
    offered = [CandidatePose(1, AWAY), CandidatePose(2, WIDE)]
    inp = _input(captured, offered, model, pairs)
    weak = choosers.weak_points(inp)
    assert not weak.point.any() and weak.seen.all()
    np.testing.assert_allclose(np.sort(weak.X, axis=0), np.sort(X, axis=0), atol=1e-6)
    assert choose("weak-triangulation", inp, chooser_rng(0, "weak-triangulation", 0)) == 1
    # unmatched keypoints with no point to take a depth from are not placed: nothing to
    # gain anywhere, so it picks as farthest-view
    bare = replace(inp, pairs=())
    assert len(choosers.weak_points(bare).X) == 0
    assert choose("weak-triangulation", bare, chooser_rng(0, "weak-triangulation", 0)) == 0


def test_random_view_is_seeded_and_every_choice_is_an_offered_candidate():
    captured = [_captured(c, k) for k, c in enumerate(_row_capture([0.0, 1.0, 2.0]))]
    offered = [CandidatePose(10 + k, c) for k, c in enumerate(_row_capture(range(3, 13)))]
    inp = _input(captured, offered)
    picks = [choose("random-view", inp, chooser_rng(7, "random-view", s)) for s in range(20)]
    again = [choose("random-view", inp, chooser_rng(7, "random-view", s)) for s in range(20)]
    assert picks == again and len(set(picks)) > 3 and all(0 <= p < 10 for p in picks)


@pytest.mark.parametrize(
    "body, rule",
    [
        ("return 7", "'one offered candidate': returned 7 (2 offered)"),
        ("return 0.0", "'one offered candidate': returned 0.0"),
        ("raise ValueError('no pose')", "failed: ValueError: no pose"),
        ("importlib.import_module('bench.evaluation.truth')", "'no ground truth'"),
    ],
)
def test_a_chooser_breaking_its_contract_or_reaching_ground_truth_fails_saying_why(body, rule):
    namespace = {"importlib": importlib}
    exec(f"def broken(inp, rng):\n    {body}\n", namespace)
    chooser("broken-view", "Broken")(namespace["broken"])
    captured = [_captured(c, k) for k, c in enumerate(_row_capture([0.0, 1.0]))]
    inp = _input(captured, [CandidatePose(5, c) for c in _row_capture([2.0, 3.0])])
    try:
        with pytest.raises(ChooserFailed) as e:
            choose("broken-view", inp, chooser_rng(0, "broken-view", 0))
    finally:
        CHOOSERS.pop("broken-view"), METHODS.pop("broken-view")
    assert rule in str(e.value) and str(e.value).startswith("view chooser broken-view")


def test_choosers_run_only_the_nbv_task_and_it_runs_alone_and_off_by_default():
    grid = BenchConfig(scenes=("table",), seeds=(0,), tasks=("nbv",))
    kinds = {METHODS[u.method].kind for u in grid.units()}
    assert kinds == {"view-chooser", "view-oracle"}
    assert "nbv" not in BenchConfig().tasks
    assert [j.task for j in BenchConfig(tasks=("tri", "nbv")).jobs("cross-view")] == ["tri"] * 2
    with pytest.raises(BenchError, match="run it alone, --tasks nbv"):
        BenchConfig(scenes=("table",), tasks=("tri", "nbv")).validate()


@pytest.mark.parametrize(
    "nbv, why",
    [
        (NbvConfig(added=(2, 1)), "increasing numbers of views from 1 to 8"),
        (NbvConfig(added=(1, 9)), "increasing numbers of views from 1 to 8"),
        (NbvConfig(between=1, added=(6,)), "the path has 5 candidates; raise nbv.between"),
        (NbvConfig(policy="all"), "a budgeted selection policy, not all"),
        (NbvConfig(policy="oracle"), "a budgeted selection policy, not oracle"),
        (NbvConfig(every=1), "nbv.every at least 2"),
    ],
)
def test_bad_nbv_settings_are_refused_in_one_line(nbv, why):
    with pytest.raises(BenchError, match=why.replace("(", r"\(")):
        RunConfig(nbv=nbv).validate()


SMALL = NbvConfig(between=1, added=(1, 2))
"""Six initial views and five candidates on an 11-view path; scored after 1 and 2 added."""
CHOSEN = ("random-view", "farthest-view", "gap-view", "weak-triangulation", "oracle-view")


@pytest.fixture(scope="module")
def nbv_run(renders_dir, tmp_path_factory):
    results = tmp_path_factory.mktemp("nbv")
    grid = BenchConfig(
        scenes=("table",),
        seeds=(0,),
        methods=CHOSEN,
        budgets=(64,),
        tasks=("nbv",),
        protocols=("multiview",),
        run=RunConfig(render=MEDIUM, nbv=SMALL),
    )
    return grid, results, bench_run(grid, results, renders_dir)


def test_a_small_nbv_run_writes_rows_of_the_contract_table3_and_the_figure(nbv_run):
    grid, results, _ = nbv_run
    runs = read_runs(results / "runs.csv")  # the runs contract, checked on reading
    assert sorted(runs["method"]) == sorted(CHOSEN) and (runs["status"] == "ok").all()
    assert (runs["candidates"] == 5).all() and (runs["initial_views"] == 6).all()
    assert (runs["views"] == 11).all()
    for score in ("completeness", "maa"):
        for k in (1, 2):
            gain = runs[f"{score}_k{k}"] - runs[f"{score}_k0"]
            np.testing.assert_allclose(runs[f"{score}_gain_k{k}"], gain)
    assert runs["completeness_k0"].nunique() == 1  # the same initial capture for every chooser
    for method in CHOSEN:
        record = json.loads(
            (results / "models" / "table-s0" / f"{method}-b64" / "prediction.json").read_text()
        )["jobs"]["nbv/multiview"]
        assert record["initial"] == [f"view_{v:02d}.png" for v in range(0, 11, 2)]
        chosen = record["chosen"]
        assert len(chosen) == 2 == len(set(chosen)) and not set(chosen) & set(record["initial"])
        assert record["captures"]["2"] == sorted(record["initial"] + chosen)
    t3 = pd.read_csv(results / "table3.csv", keep_default_na=False, na_values=[""])
    assert set(t3["method"]) == set(CHOSEN) and set(t3["k"]) == {1, 2}
    assert set(t3["baseline"]) == {"random-view", "farthest-view", "gap-view"}
    assert (results / "figure_views.png").is_file()
    assert "## Table 3: next views" in (results / "README.md").read_text()
    vocab = read_vocabulary(results)
    assert vocab.first_headline()[-1] == "nbv_maa_gain_k2"  # what transfer.csv ranks by
    summary, _ = transfer(runs.assign(scene="photos"), vocab, results)
    assert set(summary["metric"]) == {"nbv_maa_gain_k2"} and (summary["methods"] == 5).all()


def test_the_view_oracle_bounds_every_chooser_in_its_score(nbv_run):
    _, _, runs = nbv_run
    by = runs.set_index("method")
    for k in (1, 2):
        assert (
            by.loc["oracle-view", f"completeness_gain_k{k}"] >= by[f"completeness_gain_k{k}"].max()
        )


def test_rows_scored_again_from_the_stored_models_are_the_same(nbv_run, renders_dir):
    grid, results, runs = nbv_run
    again = bench_run(grid, results, renders_dir, reevaluate=True)
    assert set(again["invocation"]).isdisjoint(runs["invocation"])  # every row scored again
    scores = [c for c in runs if c.startswith(("completeness", "maa"))]
    pd.testing.assert_frame_equal(runs[scores], again[scores])


def test_on_a_dataset_with_poses_alone_the_oracle_picks_by_maa(nbv_run, renders_dir, tmp_path):
    """The same 11-view path as a dataset without per-pixel truth: every second image is
    the initial capture, completeness is NaN and the scores are the sfm task's mAA."""
    grid, _, rendered = nbv_run
    entry = render_scene("table", 0, replace(MEDIUM, views=11), renders_dir)
    full = export_dataset(entry, tmp_path / "full")
    bare = tmp_path / "path"
    for part in ("images", "sparse"):
        shutil.copytree(full / part, bare / part)
    ds = replace(
        grid,
        scenes=("path",),
        methods=("random-view", "oracle-view"),
        run=RunConfig(render=None, nbv=replace(SMALL, added=(1,), every=2)),
        datasets=(str(bare),),
    )
    runs = bench_run(ds, tmp_path / "res", renders_dir).set_index("method")
    assert runs["completeness_k0"].isna().all() and runs["maa_k0"].notna().all()
    assert runs.loc["oracle-view", "maa_gain_k1"] >= runs.loc["random-view", "maa_gain_k1"]
    assert runs["maa_k0"].iloc[0] == rendered["maa_k0"].iloc[0]  # the same initial capture


def test_the_quick_preset_offers_five_candidates_and_nbv_settings_are_set_on_the_command_line(
    capsys,
):
    from bench.cli import build_parser, main
    from bench.cli.run import run_config

    argv = ["run", "--quick", "--tasks", "nbv", "--set", "nbv.added=1,3"]
    cfg = run_config(build_parser("run").parse_args(argv)).validate()
    assert (cfg.nbv.path, cfg.nbv.added, cfg.nbv.policy) == (11, (1, 3), "cross-view")
    assert RunConfig().nbv.path == 21  # the dense regime's path, the sparse rig's six on it
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "so it is off by default" in " ".join(capsys.readouterr().out.split())
