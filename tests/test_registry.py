"""The architecture: one vocabulary, a report that reads results only, a task added in one
place, every setting reachable."""

from __future__ import annotations

import dataclasses
import shutil

import pandas as pd
import pycolmap
import pytest

from bench import BenchError, vocabulary
from bench.cli import main
from bench.runs import read_runs
from bench.unit.config import RunConfig
from tests.conftest import (
    bench_run,
    small_grid,
)

SMALL = small_grid()


# --- the architecture: one vocabulary, a report that reads results only ---------------


def test_plot_and_publish_run_without_colmap_opencv_or_mitsuba(quick_results, tmp_path):
    """The report stage reads results only: with pycolmap, cv2, mitsuba and drjit made
    unimportable, `bench plot` rewrites every table and figure (Figure 2 included) and
    `bench publish` copies them, without the evaluation stage (ground truth, point errors;
    scipy.spatial is no longer the sign of it: scipy.stats, which the tiers' Wilcoxon test
    needs, imports it itself)."""
    import subprocess
    import sys

    shutil.copytree(quick_results, tmp_path / "r")
    for name in ("table1.csv", "figure2.png", "figure3.png"):
        (tmp_path / "r" / name).unlink()
    blocked = (
        "import sys\nfor m in ('pycolmap', 'cv2', 'mitsuba', 'drjit'):\n    sys.modules[m] = None\n"
    )
    script = blocked + (
        "from bench.cli import main\n"
        f"assert main(['plot', '--results', {str(tmp_path / 'r')!r}, '--renders', "
        f"{str(quick_results.parent)!r}]) == 0\n"
        f"assert main(['publish', '--results', {str(tmp_path / 'r')!r}, '--to', "
        f"{str(tmp_path / 'p')!r}]) == 0\n"
        "loaded = {m for m, v in sys.modules.items() if v is not None}\n"
        "assert not {'pycolmap', 'cv2', 'mitsuba', 'drjit'} & loaded\n"
        "assert not [m for m in loaded if m.startswith('bench.evaluation')], loaded\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    for name in ("table1.csv", "figure3.png"):
        assert (tmp_path / "r" / name).is_file() and (tmp_path / "p" / name).is_file()
    same = (tmp_path / "r" / "table1.csv").read_bytes() == (
        quick_results / "table1.csv"
    ).read_bytes()
    assert same


def test_figure2_is_drawn_from_the_exported_model_alone(quick_results, renders_dir, tmp_path):
    from bench.report.figures import figure2, read_text_model

    runs = read_runs(quick_results / "runs.csv")
    assert figure2(runs, quick_results, renders_dir, tmp_path / "figure2") is None
    assert (tmp_path / "figure2.png").is_file()
    images, ids, X = read_text_model(quick_results / "models" / "table-s0" / "adaptive-b64")
    model = pycolmap.Reconstruction(str(quick_results / "models" / "table-s0" / "adaptive-b64"))
    assert sorted(ids) == sorted(model.points3D) and len(X) == model.num_points3D()
    for image in model.images.values():
        xy, observed = images[image.name]
        assert len(xy) == image.num_points2D()
        assert observed.sum() == sum(p.has_point3D() for p in image.points2D)


def test_a_task_is_added_in_one_place(renders_dir, tmp_path):
    """A new task is one registration in the task registry: the grid runs it, its rows
    are checked against its required metrics and their declared ranges, and Table 1 shows
    its columns; a second task of the same name is refused."""
    from bench.backend.reconstruction import known_pose_task
    from bench.unit import tasks

    def count_points(truth, model, names, protocol, poses):
        return {"observed_points": 0 if model is None else model.num_points3D()}

    vocabulary.declare_metric(vocabulary.Metric("observed_points"))
    runner = tasks.TaskRunner(
        vocabulary.Task("count", "rig", needs=("observed_points",), metrics=("observed_points",)),
        reconstruct=lambda m, cfg, protocol: known_pose_task(
            m.cams, m.names, m.xy, m.pairs, cfg, protocol
        ),
        evaluate=count_points,
    )
    tasks.register(runner)
    try:
        with pytest.raises(BenchError, match="task name 'count' is taken"):
            tasks.register(runner)
        grid = dataclasses.replace(
            SMALL, scenes=("facade",), methods=("texture",), tasks=("tri", "count")
        )
        runs = bench_run(grid, tmp_path, renders_dir)
    finally:  # the registry as it was, for the other tests
        del (
            tasks.TASK_RUNNERS["count"],
            vocabulary.TASKS["count"],
            vocabulary.METRICS["observed_points"],
        )
    counted = runs[runs["task"] == "count"].set_index("protocol")["observed_points"]
    tri = runs[runs["task"] == "tri"].set_index("protocol")["points"]
    assert (counted == tri).all() and counted.sum() > 0
    assert "count_observed_points" in pd.read_csv(tmp_path / "table1.csv").columns


@pytest.mark.parametrize(
    "setting, message",
    [
        ("backend.ratio=2", "backend.ratio must lie in (0, 1]"),
        ("backend.ratio=x", "--set backend.ratio=x: expected float"),
        ("backend.speed=1", "BackendConfig has no setting 'speed'; valid: ratio,"),
        ("backend.matcher=lightglue", "the sift pool is matched with ratio"),
        ("policy.tiles=8", "expected 2 comma-separated values"),
        ("policy.weights=1", "set its fields (weights.texture,"),
        ("signals.first_pass=2", "signals.first_pass >= 8"),
        ("ratio", "--set takes section.field=value"),
    ],
)
def test_a_bad_setting_is_one_line(setting, message, tmp_path, capsys):
    argv = ["run", "--quick", "--set", setting, "--results", str(tmp_path / "r")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists()


def test_every_setting_is_reachable_with_set_and_recorded():
    from bench.cli.common import apply_settings, settings_help

    run = apply_settings(
        RunConfig(),
        ["backend.ratio=0.7", "policy.tiles=4,3", "signals.depth_prior=none", "render.spp=4"]
        + ["policy.weights.parallax=0.5", "detector.detector=orb"],
    )
    assert (run.backend.ratio, run.policy.tiles, run.signals.depth_prior) == (0.7, (4, 3), None)
    assert (run.render.spp, run.policy.weights.parallax, run.detector.detector) == (4, 0.5, "orb")
    assert run.as_dict()["backend"]["ratio"] == 0.7  # what config.json records
    names = settings_help(RunConfig)
    assert "backend.ratio" in names and "policy.weights.texture" in names and len(names) > 25


def test_a_refused_overwrite_keeps_the_stored_predictions_and_a_bound_one_replaces_them(
    quick_results, renders_dir, tmp_path
):
    """--overwrite moves the old models and predictions aside before any unit writes (the
    workers of the new run write beside them), puts them back if the run is refused before
    its first rows, and removes them once the folder is bound to the new settings."""
    r = tmp_path / "r"
    shutil.copytree(quick_results, r)
    stored = sorted(p.relative_to(r) for p in (r / "models").rglob("prediction.json"))
    with pytest.raises(BenchError, match="exceeds every candidate pool"):
        bench_run(dataclasses.replace(SMALL, budgets=(10**6,)), r, renders_dir, overwrite=True)
    assert sorted(p.relative_to(r) for p in (r / "models").rglob("prediction.json")) == stored
    one = dataclasses.replace(SMALL, scenes=("table",), methods=("texture",), tasks=("tri",))
    bench_run(one, r, renders_dir, overwrite=True)
    assert [p.parent.name for p in (r / "models").rglob("prediction.json")] == ["texture-b64"]
    assert not list(r.glob(".models-replaced-*")) and len(read_runs(r / "runs.csv")) == 2


def test_every_kind_says_once_what_its_budget_means():
    """B means what the method's kind declares (`budget_means`): every kind of the package
    says it, a whole-pool method's is the pool's, an equal-count method's its peer's."""
    from bench.vocabulary import KIND_BUDGET, KINDS, METHODS, WHOLE_POOL_BUDGET, budget_means

    assert set(KIND_BUDGET) == set(KINDS)
    assert budget_means(METHODS["all"]) == budget_means(METHODS["colmap"]) == WHOLE_POOL_BUDGET
    assert budget_means(METHODS["texture"]) == KIND_BUDGET[vocabulary.PER_VIEW]
    equal = next(m for m in METHODS.values() if m.kind == vocabulary.EQUAL_COUNT)
    assert "peer" in budget_means(equal) and all(budget_means(m) for m in METHODS.values())
    assert vocabulary.declare_kind("house-test-kind", "a kind", budget="b") == "house-test-kind"
    assert KIND_BUDGET.pop("house-test-kind") == "b"
    del KINDS["house-test-kind"]
