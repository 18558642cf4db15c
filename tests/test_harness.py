"""`bench run` and `bench plot`: files, resumption, configuration guard, reproducibility."""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from bench import BenchError, harness
from bench.cli import main
from bench.harness import BenchConfig, run_benchmark
from bench.pipeline import RunConfig
from tests.conftest import MEDIUM

SMALL = BenchConfig(
    scenes=("table", "facade"), seeds=1, budgets=(64,), run=RunConfig(render=MEDIUM)
)
TIMING = [
    "render_s_per_view",
    "detect_ms",
    "signals_ms",
    "select_ms",
    "match_ms",
    "verify_ms",
    "triangulate_ms",
    "evaluate_ms",
    "wall_ms",
]


@pytest.fixture(scope="module")
def quick_results(renders_dir, tmp_path_factory):
    results = tmp_path_factory.mktemp("results")
    run_benchmark(SMALL, results, renders_dir)
    return results


def test_quick_run_writes_every_file_with_documented_columns(quick_results):
    for name in (
        "runs.csv",
        "table1.csv",
        "table2.csv",
        "figure2.png",
        "figure3.png",
        "figure3.pdf",
        "manifest.json",
        "config.json",
    ):
        assert (quick_results / name).is_file(), name
    runs = pd.read_csv(quick_results / "runs.csv")
    assert len(runs) == 2 * 5 and set(runs["policy"]) == {
        "random",
        "texture",
        "grid",
        "adaptive",
        "all",
    }
    assert {"render_key", "config_hash", "status", "failure", *TIMING} <= set(runs.columns)
    t1 = pd.read_csv(quick_results / "table1.csv")
    assert {
        "strategy",
        "rmse",
        "acc_completeness_pct",
        "inlier_pct",
        "coverage_pct",
        "runtime_proxy",
        "wall_ms",
        "rmse_ci95",
    } <= set(t1.columns)
    assert list(t1["policy"]) == ["random", "texture", "grid", "adaptive", "all"]
    t2 = pd.read_csv(quick_results / "table2.csv")
    assert list(t2.columns[:2]) == ["scene", "budget"] and set(t2["scene"]) == {"table", "facade"}
    assert {
        "adaptive_rmse",
        "best_baseline_rmse",
        "best_baseline_rmse_policy",
        "adaptive_acc_completeness_pct",
        "best_baseline_acc_completeness_pct",
        "best_baseline_acc_completeness_policy",
    } <= set(t2.columns)
    manifest = json.loads((quick_results / "manifest.json").read_text())
    assert {"versions", "variant", "host", "config", "seeds", "git_commit", "seconds"} <= set(
        manifest
    )
    assert manifest["seconds"]["total"] > 0 and "render" in manifest["seconds"]
    for policy in ("adaptive", "all"):
        assert (quick_results / "models" / "table-s0" / f"{policy}-b64" / "points3D.txt").is_file()


def test_plot_rebuilds_the_tables_from_runs_csv_alone(quick_results, tmp_path, renders_dir, capsys):
    shutil.copy(quick_results / "runs.csv", tmp_path / "runs.csv")
    assert main(["plot", "--results", str(tmp_path), "--renders", str(renders_dir)]) == 0
    for name in ("table1.csv", "table2.csv"):
        assert (tmp_path / name).read_bytes() == (quick_results / name).read_bytes()
    assert (tmp_path / "figure3.png").is_file()
    assert "figure2.png not drawn" in capsys.readouterr().out  # no exported model was copied


def test_several_budgets_give_a_budget_figure(quick_results, tmp_path, renders_dir):
    from bench.report import write_report

    runs = pd.read_csv(quick_results / "runs.csv")
    write_report(pd.concat([runs, runs.assign(budget=32)]), tmp_path, renders_dir)
    assert (tmp_path / "figure_budget.png").is_file()
    t1 = pd.read_csv(tmp_path / "table1.csv")
    assert sorted(set(t1["budget"])) == [32, 64] and len(t1) == 10


def test_same_command_gives_identical_metrics(quick_results, renders_dir, tmp_path):
    run_benchmark(SMALL, tmp_path, renders_dir)
    a, b = (pd.read_csv(d / "runs.csv") for d in (quick_results, tmp_path))
    metrics = [c for c in a.columns if c not in TIMING]
    pd.testing.assert_frame_equal(a[metrics], b[metrics])


def test_interrupted_run_resumes_without_redoing_rows(renders_dir, tmp_path, monkeypatch):
    calls = []
    real = harness.run_one

    def interrupt_after_three(*args, **kwargs):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(args[4:7])
        return real(*args, **kwargs)

    monkeypatch.setattr(harness, "run_one", interrupt_after_three)
    with pytest.raises(KeyboardInterrupt):
        run_benchmark(SMALL, tmp_path, renders_dir)
    assert len(pd.read_csv(tmp_path / "runs.csv")) == 3
    calls.clear()
    monkeypatch.setattr(harness, "run_one", lambda *a, **k: calls.append(a[4:7]) or real(*a, **k))
    run_benchmark(SMALL, tmp_path, renders_dir)
    assert len(calls) == 7
    runs = pd.read_csv(tmp_path / "runs.csv")
    assert len(runs) == 10 and not runs.duplicated(["scene", "seed", "policy", "budget"]).any()
    calls.clear()
    rendered = []
    monkeypatch.setattr(harness, "render_scene", lambda *a, **k: rendered.append(a))
    run_benchmark(SMALL, tmp_path, renders_dir)  # all done: nothing rendered, nothing run
    assert calls == [] and rendered == []


def test_another_configuration_into_the_same_directory_is_refused(
    quick_results, renders_dir, tmp_path
):
    shutil.copytree(quick_results, tmp_path / "r")
    other = BenchConfig(scenes=("table",), seeds=1, budgets=(32,), run=RunConfig(render=MEDIUM))
    with pytest.raises(
        BenchError, match="holds results of another configuration .*budgets.*--overwrite"
    ):
        run_benchmark(other, tmp_path / "r", renders_dir)
    assert len(pd.read_csv(tmp_path / "r" / "runs.csv")) == 10  # nothing lost
    run_benchmark(other, tmp_path / "r", renders_dir, overwrite=True)
    assert len(pd.read_csv(tmp_path / "r" / "runs.csv")) == 5


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "runs.csv not found"),
        ("scene,seed\n\x00\x01,\n", "malformed: missing columns"),
        ('scene,seed,policy\n"unclosed', "malformed"),
    ],
)
def test_plot_rejects_bad_runs_csv_in_one_line(tmp_path, capsys, content, message):
    if content is not None:
        (tmp_path / "runs.csv").write_text(content)
    assert main(["plot", "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["run", "--policies", "best"],
            "unknown policy 'best'; valid: random, texture, grid, adaptive, all",
        ),
        (["run", "--budget", "0"], "budget must be positive"),
        (["run", "--budget", "12x"], "budget must be positive integers"),
        (["run", "--scenes", "moon"], "unknown scene 'moon'"),
        (["run", "--detector", "surf"], "invalid choice: 'surf'"),
        (["run", "--weights", "0.3,x,0,0,0"], "weights must be five numbers"),
        (["run", "--weights", "0.3,0.2"], "weights must be five numbers"),
    ],
)
def test_run_bad_input_is_one_clear_line(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main([*argv, "--results", str(tmp_path / "r")]))
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists()
