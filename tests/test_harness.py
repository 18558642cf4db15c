"""The harness: one run end to end (a complete row, an export that matches it), then `bench
run` and `bench plot`: files, resumption, configuration guard, reproducibility."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
import pytest

from bench import BenchError, vocabulary
from bench.backend.reconstruction import known_pose_model
from bench.cli import build_parser, main
from bench.cli.common import LATEST, PUBLISHED, QUICK, REGIMES, parse_list, regime_folder
from bench.evaluation.layers import read_layers
from bench.evaluation.truth import SceneTruth
from bench.frontend import plugins
from bench.frontend import policies as registry
from bench.frontend.geometry import RIG
from bench.frontend.policies import PolicyConfig
from bench.frontend.stage import front_end
from bench.harness import evaluate, execute
from bench.harness import grid as harness
from bench.harness import predict as prediction
from bench.harness.config import RunConfig
from bench.harness.execute import Work, compute_unit
from bench.harness.grid import BenchConfig
from bench.harness.predict import LoadedScene, export_model
from bench.render import entry as render
from bench.report import figures
from bench.report.write import publish, write_report
from bench.results import Workspace, read_runs
from bench.vocabulary import KEY, Job, Unit, Vocabulary
from tests.conftest import MEDIUM, TINY, bench_run, synthetic_rig


def spy(monkeypatch, calls: list, what=lambda unit: (unit.method, unit.budget)):
    """Record `what` of every unit that is predicted (selected, matched, mapped)."""
    real = execute.predict
    monkeypatch.setattr(
        execute,
        "predict",
        lambda scene, unit, *a: calls.append(what(unit)) or real(scene, unit, *a),
    )


# --- one run ------------------------------------------------------------------------

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
    "task_ms",
    "evaluate_ms",
    "render_s_per_view",
    "accuracy_pct",
]


@pytest.fixture(scope="module")
def table_run(medium_entry, tmp_path_factory):
    entry = medium_entry("table")
    cfg = RunConfig()
    fe = front_end(entry, cfg.detector, cfg.signals, tmp_path_factory.mktemp("fe"))
    truth = SceneTruth.build([v.camera for v in fe.views], read_layers(entry), fe.pools)
    out = tmp_path_factory.mktemp("models")

    def run(policy: str, budget: int = 128):
        unit, work = Unit("table", 0, policy, budget), Work((Job("tri", "multiview"),))
        (row,) = compute_unit(
            LoadedScene(entry, {RIG: fe}, truth), unit, work, cfg, Workspace(out, out)
        )
        return row, out / "models" / "table-s0" / f"{policy}-b{budget}"

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


def test_the_order_of_a_policys_indices_does_not_change_any_metric(medium_entry, tmp_path):
    """A selection is a set: the same indices listed forwards and backwards give the same
    verified matches, points and poses (they did not: 348 against 350 verified matches)."""
    module = tmp_path / "orders.py"
    module.write_text(
        "import numpy as np\n"
        "from bench.frontend.policies import policy\n\n"
        "def strongest(inp, budget):\n"
        "    return np.argsort(-inp.candidates.response, kind='stable')[:budget]\n\n"
        "@policy('forwards')\n"
        "def forwards(inp, budget, rng, cfg):\n"
        "    return strongest(inp, budget)\n\n"
        "@policy('backwards')\n"
        "def backwards(inp, budget, rng, cfg):\n"
        "    return strongest(inp, budget)[::-1]\n"
    )
    entry = medium_entry("table")
    cfg = RunConfig(policy=dataclasses.replace(RunConfig().policy, modules=(str(module),)))
    fronts = {
        g: front_end(entry, cfg.detector, cfg.signals, tmp_path / "fe", g)
        for g in ("rig", "images")
    }
    truth = SceneTruth.build(
        [v.camera for v in fronts["rig"].views], read_layers(entry), fronts["rig"].pools
    )
    work = Work((Job("tri", "multiview"), Job("sfm", "multiview")))
    scene = LoadedScene(entry, fronts, truth)
    rows = {
        p: compute_unit(
            scene, Unit("table", 0, p, 128), work, cfg, Workspace(tmp_path / p, tmp_path)
        )
        for p in ("forwards", "backwards")
    }
    skip = {"method", "failure", "prediction_hash"} | {
        k for k in rows["forwards"][0] if k.endswith("_ms")
    }
    for a, b in zip(rows["forwards"], rows["backwards"]):
        assert a["verified_matches"] > 0
        assert {k: v for k, v in a.items() if k not in skip} == pytest.approx(
            {k: v for k, v in b.items() if k not in skip}, nan_ok=True
        )


def test_budgeted_images_txt_lists_every_selected_keypoint(table_run):
    _, model_dir = table_run("texture", 64)
    model = pycolmap.Reconstruction(str(model_dir))
    assert [img.num_points2D() for img in model.images.values()] == [64] * 6


def test_exported_model_reads_back_with_pycolmap(tmp_path):
    cams, X = synthetic_rig()
    model = known_pose_model(cams, [f"v{k}.png" for k in range(4)], [c.project(X)[0] for c in cams])
    export_model(model, tmp_path / "m")
    back = pycolmap.Reconstruction(str(tmp_path / "m"))
    assert back.num_images() == 4 and back.image(1).num_points2D() == len(X)
    assert (tmp_path / "m" / "points.ply").is_file() and (tmp_path / "m" / "points3D.txt").is_file()


# --- the grid -----------------------------------------------------------------------

SMALL = BenchConfig(
    scenes=("table", "facade"),
    seeds=(0,),
    methods=("random", "texture", "grid", "adaptive", "all", "oracle", "colmap", "colmap-b"),
    budgets=(64,),
    run=RunConfig(render=MEDIUM),
)
TIMING = [
    "render_s_per_view",
    "detect_ms",
    "signals_ms",
    "select_ms",
    "match_ms",
    "verify_ms",
    "task_ms",
    "evaluate_matches_ms",
    "evaluate_ms",
    "wall_ms",
    "invocation",
    "row_checksum",
]
POLICIES = ["random", "texture", "grid", "adaptive", "oracle", "colmap-b", "all", "colmap"]
ROWS = 2 * (6 * 3 * 2 + 2 * 2 * 2)  # scenes x (selections x 3 tasks + peers x 2) x protocols


@pytest.fixture(scope="module")
def quick_results(renders_dir, tmp_path_factory):
    results = tmp_path_factory.mktemp("results")
    bench_run(SMALL, results, renders_dir)
    return results


def test_quick_run_writes_every_file_with_documented_columns(quick_results):
    for name in (
        "runs.csv",
        "table1.csv",
        "table1_twoview.csv",
        "table2.csv",
        "paired.csv",
        "figure2.png",
        "figure3.png",
        "figure3.pdf",
        "manifest.json",
        "config.json",
    ):
        assert (quick_results / name).is_file(), name
    runs = pd.read_csv(quick_results / "runs.csv")
    assert len(runs) == ROWS and set(runs["method"]) == set(POLICIES)
    assert set(runs.loc[runs["method"] == "all", "budget"]) == {0}  # one run, the whole pool
    assert set(zip(runs["task"], runs["protocol"])) == {
        (t, p) for t in ("tri", "sfm", "pairs") for p in ("multiview", "twoview")
    }
    assert set(runs.loc[runs["method"].str.startswith("colmap"), "task"]) == {"sfm", "pairs"}
    pairs = runs[runs["task"] == "pairs"]  # scored from the poses stored with the prediction
    assert pairs["auc_10"].between(0, 1).all() and (pairs["pairs_estimated"] > 0).any()
    assert (pairs.loc[pairs["status"] == "failed", "auc_20"] == 0).all()  # scored, all missing
    capped = runs.loc[runs["method"] == "colmap-b", "keypoints_per_view"]
    assert len(capped) and (capped == 64).all()  # a hard cap: exactly B per view
    assert runs["maa"].notna().sum() == runs["task"].eq("sfm").sum()  # never NaN, failed or not
    assert {
        "render_key",
        "prediction_hash",
        "evaluation_hash",
        "status",
        "failure",
        *TIMING,
    } <= set(runs.columns)
    t1 = pd.read_csv(quick_results / "table1.csv")
    assert {
        "strategy",
        "rmse",
        "acc_completeness_pct",
        "inlier_pct",
        "coverage_pct",
        "runtime_proxy",
        "wall_ms",
        "rmse_lo",
        "rmse_hi",
        "accuracy_pct",
        "completeness_vs_oracle_pct",
    } <= set(t1.columns)
    assert list(t1["method"]) == POLICIES
    t2 = pd.read_csv(quick_results / "table2.csv")
    assert list(t2.columns[:2]) == ["scene", "budget"]
    assert set(t2["scene"]) == {"table", "facade", "all scenes"}
    assert {
        "adaptive_rmse",
        "best_baseline_rmse",
        "best_baseline_rmse_policy",
        "adaptive_acc_completeness_pct",
        "best_baseline_acc_completeness_pct",
        "best_baseline_acc_completeness_policy",
    } <= set(t2.columns)
    manifest = json.loads((quick_results / "manifest.json").read_text())
    keys = {"versions", "variant", "host", "settings", "grid", "git_commit", "seconds"}
    assert keys | {"invocations"} <= set(manifest)
    assert manifest["seconds"]["total"] > 0 and "render" in manifest["seconds"]
    for run in ("adaptive-b64", "all-b0", "oracle-b64/twoview"):
        assert (quick_results / "models" / "table-s0" / run / "points3D.txt").is_file()
    # every job's model in its own folder (sfm's two protocols once shared one)
    ws, mapped = Workspace(quick_results, quick_results), runs[(runs["task"] == "sfm")]
    for r in mapped[mapped["status"] == "ok"].itertuples():
        folder = ws.model_dir(Unit(r.scene, r.seed, r.method, r.budget), Job(r.task, r.protocol))
        model = pycolmap.Reconstruction(str(folder))
        assert (model.num_reg_images(), model.num_points3D()) == (r.registered_views, r.points)
    assert set(mapped.loc[mapped["status"] == "ok", "protocol"]) == {"multiview", "twoview"}


def test_plot_rebuilds_the_tables_from_runs_csv_alone(quick_results, tmp_path, renders_dir, capsys):
    for name in ("runs.csv", "vocabulary.json"):
        shutil.copy(quick_results / name, tmp_path / name)
    assert main(["plot", "--results", str(tmp_path), "--renders", str(renders_dir)]) == 0
    for name in ("table1.csv", "table2.csv"):
        assert (tmp_path / name).read_bytes() == (quick_results / name).read_bytes()
    assert (tmp_path / "figure3.png").is_file()
    assert "figure2.png not drawn" in capsys.readouterr().err  # no exported model was copied


def test_several_budgets_give_a_budget_figure(quick_results, tmp_path, renders_dir):
    shutil.copy(quick_results / "vocabulary.json", tmp_path)
    runs = pd.read_csv(quick_results / "runs.csv")
    budgeted = runs[runs["budget"] > 0]
    write_report(pd.concat([runs, budgeted.assign(budget=32)]), tmp_path, renders_dir)
    assert (tmp_path / "figure_budget.png").is_file()
    t1 = pd.read_csv(tmp_path / "table1.csv")
    assert sorted(set(t1["budget"])) == [0, 32, 64] and len(t1) == 2 * 6 + 2


def test_same_command_gives_identical_metrics(quick_results, renders_dir, tmp_path):
    bench_run(SMALL, tmp_path, renders_dir)
    a, b = (pd.read_csv(d / "runs.csv") for d in (quick_results, tmp_path))
    metrics = [c for c in a.columns if c not in TIMING]
    pd.testing.assert_frame_equal(a[metrics], b[metrics])


def test_interrupted_run_resumes_without_redoing_rows(renders_dir, tmp_path, monkeypatch):
    calls = []
    real = execute.predict

    def interrupt_after_three(scene, unit, *args):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(unit)
        return real(scene, unit, *args)

    monkeypatch.setattr(execute, "predict", interrupt_after_three)
    with pytest.raises(KeyboardInterrupt):
        bench_run(SMALL, tmp_path, renders_dir)
    assert len(pd.read_csv(tmp_path / "runs.csv")) == 3 * 6  # tasks x protocols
    monkeypatch.setattr(execute, "predict", real)
    calls.clear()
    spy(monkeypatch, calls)
    bench_run(SMALL, tmp_path, renders_dir)
    assert len(calls) == 2 * 8 - 3  # every unit of both scenes, but the three done
    runs = pd.read_csv(tmp_path / "runs.csv")
    assert len(runs) == ROWS and not runs.duplicated(list(KEY)).any()
    calls.clear()
    rendered = []
    monkeypatch.setattr(harness, "render_scene", lambda *a, **k: rendered.append(a))
    bench_run(SMALL, tmp_path, renders_dir)  # all done: nothing rendered, nothing run
    assert calls == [] and rendered == []


def test_growing_a_results_folder_runs_only_the_new_rows(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """A new budget needs no --overwrite and runs only its rows; a changed setting
    is refused, naming the setting."""
    shutil.copytree(quick_results, tmp_path / "r")
    calls = []
    spy(monkeypatch, calls)
    grown = dataclasses.replace(SMALL, scenes=("table",), budgets=(64, 32))
    bench_run(grown, tmp_path / "r", renders_dir)
    assert sorted(calls) == [(p, 32) for p in sorted(POLICIES[:6])]
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert len(runs) == ROWS + 5 * 6 + 4  # the new budget's selections and its colmap-b
    other = dataclasses.replace(SMALL, run=RunConfig(render=dataclasses.replace(MEDIUM, spp=4)))
    with pytest.raises(BenchError, match=r"other settings \(render.spp: 16 there, 4 now\)"):
        bench_run(other, tmp_path / "r", renders_dir)
    assert len(pd.read_csv(tmp_path / "r" / "runs.csv")) == len(runs)  # nothing lost


def test_rows_computed_by_other_code_are_computed_again(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """The key that decides whether a row is finished covers the stages' code."""
    shutil.copytree(quick_results, tmp_path / "r")
    monkeypatch.setattr(prediction, "shared_code_hash", lambda: "another-code")
    calls = []
    spy(monkeypatch, calls)
    bench_run(dataclasses.replace(SMALL, scenes=("table",)), tmp_path / "r", renders_dir)
    assert len(calls) == 8  # every unit of the table scene, again
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert len(runs) == ROWS // 2  # one hash per method: its own code and settings
    assert runs.groupby("method")["prediction_hash"].nunique().max() == 1


def test_a_changed_scene_is_computed_again_and_no_other(
    quick_results, renders_dir, tmp_path, monkeypatch, capsys
):
    """A row records the render entry it was computed on: a scene whose generator,
    parameters or render settings changed since (here its render code) is rendered and
    computed again; the other scene's rows are kept as they are."""
    shutil.copytree(quick_results, tmp_path / "r")
    real = render.render_code_hash
    monkeypatch.setattr(render, "render_code_hash", lambda s: real(s) + "-edited" * (s == "table"))
    calls = []
    spy(monkeypatch, calls, what=lambda unit: unit.scene)
    runs = bench_run(SMALL, tmp_path / "r", renders_dir)
    assert calls == ["table"] * 8
    assert "the scene table (its generator, parameters or render settings) changed" in (
        capsys.readouterr().err
    )
    before = read_runs(quick_results / "runs.csv").set_index(list(KEY))["render_key"]
    after = runs.set_index(list(KEY))["render_key"].reindex(before.index)
    table = before.index.get_level_values("scene") == "table"
    assert (after[table] != before[table]).all() and (after[~table] == before[~table]).all()


def test_a_changed_metric_rescores_the_stored_predictions_alone(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """Scores apart from predictions: a new evaluation hash (a metric edited), or
    --reevaluate, scores every row again from the stored predictions without selecting,
    matching or mapping, and gives the same metrics."""
    shutil.copytree(quick_results, tmp_path / "r")
    calls = []
    spy(monkeypatch, calls)
    monkeypatch.setattr(evaluate, "evaluation_hash", lambda: "another-metric")
    monkeypatch.setattr(harness, "evaluation_hash", lambda: "another-metric")
    again = bench_run(SMALL, tmp_path / "r", renders_dir)
    assert calls == [] and set(again["evaluation_hash"]) == {"another-metric"}
    before = read_runs(quick_results / "runs.csv")
    metrics = [c for c in before.columns if c not in TIMING and c != "evaluation_hash"]
    pd.testing.assert_frame_equal(before[metrics], again[metrics])
    bench_run(SMALL, tmp_path / "r", renders_dir, reevaluate=True)
    assert calls == []
    shutil.rmtree(tmp_path / "r" / "models" / "table-s0" / "texture-b64")  # its prediction lost
    bench_run(SMALL, tmp_path / "r", renders_dir, reevaluate=True)
    assert calls == [("texture", 64)]  # predicted again; nothing else


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "runs.csv not found"),
        ("scene,seed\n\x00\x01,\n", "damaged: its header lacks method"),
        ('scene,seed,method\n"unclosed', "damaged: its header lacks"),
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
            ["run", "--methods", "best"],
            "unknown method 'best'; valid: random, texture, grid, adaptive, ",
        ),
        (
            ["run", "--protocols", "threeview"],
            "unknown protocol 'threeview'; valid: multiview, twoview",
        ),
        (["run", "--budget", "0"], "budget must be positive"),
        (["run", "--budget", "12x"], "--budget takes one comma-separated list"),
        (["run", "--budget", "128,,256"], "e.g. --budget 128,256,512"),
        (["run", "--scenes", "table", "facade"], "list options take one comma-separated list"),
        (["run", "--seeds", "-1"], "seeds must be non-negative integers"),
        (["run", "--scenes", "moon"], "unknown scene 'moon'"),
        (["run", "--detector", "surf"], "invalid choice: 'surf'"),
        (["run", "--weights", "0.3,x,0,0,0"], "is not a list of float"),
        (["run", "--weights", "0.3,0.2"], "weights must be five numbers"),
        (["run", "--seeds", "3-1"], "the range 3-1 is empty (write it low-high)"),
        (["train-weights", "--seeds", "5-3"], "the range 5-3 is empty"),
        (["run", "--scheduler", "x:1", "--workers", "2"], "--workers does not apply"),
        (["run", "--scheduler", "notanaddress"], "cannot reach the Dask scheduler notanaddress"),
        (["run", "--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler tcp://"),
    ],
)
def test_run_bad_input_is_one_clear_line(argv, message, tmp_path, capsys):
    where = ["--results", str(tmp_path / "r")] if argv[0] == "run" else []
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main([*argv, *where]))
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--results", "{file}"],
        ["run", "--results", "{file}/sub"],
        ["run", "--renders", "{file}"],
        ["plot", "--results", "{file}"],
        ["publish", "--results", "{file}"],
        ["publish", "--to", "{file}"],
        ["upgrade", "--results", "{file}"],
        ["export", "table", "--out", "{file}"],
    ],
)
def test_a_file_where_a_folder_belongs_is_named(argv, tmp_path, capsys):
    """`--results FILE` said only `File exists` (or that runs.csv was not found)."""
    file = tmp_path / "notes.txt"
    file.write_text("mine\n")
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main([a.format(file=file) for a in argv]))
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1
    assert f"{argv[-2]}: {file}" in err[0] and "is a file; give a folder" in err[0]
    assert file.read_text() == "mine\n" and os.listdir(tmp_path) == ["notes.txt"]


def test_version_names_the_distribution(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and "kpbudget-bench" in capsys.readouterr().out


# --- statistics -----------------------------------------------------------------------


def test_cells_stock_colmap_cannot_map_are_marked_and_left_out_of_the_sfm_means():
    from bench.report.tables import headline_frame, paired_sfm, table1, table_scenes
    from bench.results import mark_reference

    rows = []
    # stock COLMAP maps seed 0; seed 1 it registers in part, seed 2 with wrong poses
    for seed, ref, ref_maa in ((0, 6, 1.0), (1, 2, 0.3), (2, 6, 0.1)):
        cell = dict(scene="s", seed=seed, task="sfm", protocol="multiview", views=6, status="ok")
        rows.append(cell | dict(method="colmap", budget=0, registered_views=ref, maa=ref_maa))
        for policy, maa in (("texture", 0.5), ("adaptive", 0.7), ("colmap-b", 0.4)):
            maa += 0.2 * seed
            rows.append(cell | dict(method=policy, budget=64, registered_views=6, maa=maa))
    table = mark_reference(pd.DataFrame(rows), vocabulary.Vocabulary.current())
    maps = table.groupby("seed")["reference_maps"].agg(set).to_dict()
    assert maps == {0: {1}, 1: {0}, 2: {0}}
    vocab = vocabulary.Vocabulary.current()
    frame = headline_frame(table, vocab)
    t1 = table1(frame, vocab).set_index("method")
    assert t1.loc["texture", "sfm_maa"] == 0.5 and t1.loc["texture", "runs"] == 3
    assert t1.loc["texture", "sfm_excluded_runs"] == 2
    pairs = paired_sfm(frame, vocab).set_index(["scene", "method", "baseline", "metric"])
    vs_texture = pairs.loc[("all scenes", "adaptive", "texture", "sfm_maa")]
    assert vs_texture["n"] == 1 and vs_texture["mean_diff"] == pytest.approx(0.2)
    assert pairs.loc[("s", "texture", "colmap-b", "sfm_maa"), "mean_diff"] == pytest.approx(0.1)
    scenes = table_scenes(frame, vocab).set_index(["method", "budget"])
    assert scenes.loc[("texture", 64), "sfm_excluded_seeds"] == 2
    assert scenes.loc[("texture", 64), "sfm_maa"] == 0.5


def test_a_reference_at_the_exclusion_boundary_maps():
    """Stock COLMAP maps a cell when it registers every view with mAA of at least 0.5:
    exactly 0.5 maps, just below does not, nor every view but one at mAA 1."""
    from bench.results import mark_reference

    cells = {0: (6, 0.5), 1: (6, 0.5 - 1e-9), 2: (5, 1.0), 3: (6, 1.0)}
    rows = [
        dict(scene="s", seed=seed, task="sfm", protocol="multiview", views=6, status="ok")
        | dict(method="colmap", budget=0, registered_views=reg, maa=maa)
        for seed, (reg, maa) in cells.items()
    ]
    table = mark_reference(pd.DataFrame(rows), vocabulary.Vocabulary.current())
    assert table.set_index("seed")["reference_maps"].to_dict() == {0: 1, 1: 0, 2: 0, 3: 1}


def test_kendall_tau_and_its_interval_on_hand_made_rankings():
    from bench.report.transfer import kendall_tau, tau_interval

    assert kendall_tau([1, 2, 3, 4], [10, 20, 30, 40]) == 1
    assert kendall_tau([1, 2, 3, 4], [4, 3, 2, 1]) == -1
    assert kendall_tau([1, 2, 3, 4], [1, 3, 2, 4]) == pytest.approx(4 / 6)  # 5 of 6 agree
    assert kendall_tau([1, 1, 2], [1, 2, 3]) == pytest.approx(2 / math.sqrt(2 * 3))  # tau-b
    assert math.isnan(kendall_tau([1, 1, 1], [1, 2, 3]))
    assert tau_interval(np.arange(6.0), np.arange(6.0)) == (1.0, 1.0)
    lo, hi = tau_interval(np.arange(6.0), np.array([0, 2, 1, 3, 5, 4.0]))
    assert -1 <= lo < kendall_tau(np.arange(6.0), np.array([0, 2, 1, 3, 5, 4.0])) < hi <= 1


def test_a_budget_above_every_pool_is_refused_in_one_line(tmp_path, capsys):
    tiny = ["--width", "64", "--height", "48", "--spp", "2", "--max-depth", "2"]
    argv = [
        "run",
        "--scenes",
        "table",
        "--seeds",
        "0",
        "--budget",
        "100000",
        "--workers",
        "1",
        *tiny,
    ]
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "budget 100000 exceeds every candidate pool of table seed 0" in err[-1]
    assert not (tmp_path / "r").exists()  # a refused run binds no folder to its settings
    other = ["--budget", "16", "--spp", "3", "--methods", "texture", "--tasks", "tri"]
    argv = [*argv[:5], *argv[7:], "--protocols", "multiview"]  # the same, less the budget
    assert main([*argv, *other, "--results", str(tmp_path / "r"), "--renders", str(tmp_path)]) == 0
    assert (
        json.loads((tmp_path / "r" / "config.json").read_text())["settings"]["render"]["spp"] == 3
    )


def test_a_second_run_into_a_folder_in_use_is_refused_in_one_line(tmp_path, capsys):
    """Two runs into one folder at once lost the first run's rows; now the second is
    refused while the first holds the folder (as another process would hold it)."""
    from bench.files import exclusive

    results = tmp_path / "r"
    results.mkdir()
    with exclusive(results / ".bench-run.lock", "the first run"):
        argv = ["run", "--quick", "--scenes", "table", "--methods", "texture"]
        assert main([*argv, "--results", str(results), "--renders", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"results folder {results} is in use by another bench" in err[0]
    assert sorted(p.name for p in results.iterdir()) == []  # nothing written, lock released


def test_nothing_to_compute_is_said_in_one_line(tmp_path, capsys):
    argv = ["run", "--quick", "--methods", "colmap", "--tasks", "tri"]
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and "nothing to compute" in err[0] and "peers run only sfm, pairs" in err[0]
    )


# --- the harness cannot publish wrong numbers ----------------------------------------


def _cut(path: Path, row: int) -> str:
    """Cut `runs.csv` in the middle of data row `row`; return the cut line."""
    lines = path.read_text().splitlines()
    cut = lines[row][: len(lines[row]) // 2]
    path.write_text("\n".join([*lines[:row], cut]) + "\n")
    return cut


def test_a_damaged_runs_csv_is_refused_naming_the_row_and_set_aside_on_request(
    quick_results, renders_dir, tmp_path, capsys
):
    r = tmp_path / "r"
    shutil.copytree(quick_results, r)
    before = (r / "table1.csv").read_bytes()
    cut = _cut(r / "runs.csv", 30)
    medium = ["--width", "320", "--height", "240", "--spp", "16", "--max-depth", "2"]
    grid = ["run", "--scenes", "table,facade", "--seeds", "0", "--budget", "64", *medium]
    for argv in (["plot"], grid):
        assert main([*argv, "--results", str(r), "--renders", str(renders_dir)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert f"{r / 'runs.csv'} is damaged: row at line 31" in err[-1]
    assert (r / "table1.csv").read_bytes() == before  # nothing published from it
    bench_run(SMALL, r, renders_dir, set_aside=True)
    assert cut in (r / "runs.damaged.csv").read_text()
    runs = read_runs(r / "runs.csv")
    assert len(runs) == ROWS and not runs.duplicated(list(KEY)).any()  # recomputed
    # a column removed: refused in one line, no traceback
    df = pd.read_csv(r / "runs.csv").drop(columns=["rmse", "status"])
    df.to_csv(r / "runs.csv", index=False)
    assert main(["plot", "--results", str(r), "--renders", str(renders_dir)]) == 2
    assert "its header lacks status" in capsys.readouterr().err


def test_repeated_list_items_run_once(capsys):
    assert parse_list("--seeds", "0,1,0,1-2", int) == (0, 1, 2)
    assert parse_list("--methods", "texture,texture", str) == ("texture",)
    assert "--seeds repeats 0, 1; each runs once" in capsys.readouterr().err


def test_runs_never_write_the_published_snapshot():
    for argv in (["run"], ["publish"]):  # resolved by the regime: results/latest(-dense)
        assert build_parser().parse_args(argv).results is None
    for argv in (["plot"], ["gallery"]):
        args = build_parser().parse_args(argv)
        target = args.out if argv == ["gallery"] else args.results
        assert PUBLISHED not in target.parents and target != PUBLISHED
    for regime in REGIMES:
        published = regime_folder(PUBLISHED, regime)
        assert published not in {regime_folder(f, r) for f in (LATEST, QUICK) for r in REGIMES}


def test_a_regime_sets_the_views_seeds_and_folders_that_are_not_given(tmp_path, monkeypatch):
    """`--regime dense`: 21 views on each path, seeds 0,1, results/latest-dense, published
    to results/published-dense; an option given wins over the regime."""
    from bench.cli import publish
    from bench.cli.run import run_config

    parse = build_parser().parse_args
    assert run_config(parse(["run", "--regime", "dense"])).render.views == 21
    assert run_config(parse(["run"])).render.views == REGIMES["sparse"][0] == 6
    assert run_config(parse(["run", "--regime", "dense", "--views", "11"])).render.views == 11
    monkeypatch.chdir(tmp_path)
    with pytest.raises(BenchError, match="results/latest-dense/runs.csv not found"):
        publish.run(parse(["publish", "--regime", "dense"]))
    assert not (tmp_path / "results").exists()


def test_publish_copies_a_checked_folder_and_removes_stale_files(quick_results, tmp_path):
    snap = tmp_path / "published"
    snap.mkdir()
    (snap / "figure_budget.png").write_bytes(b"stale")  # quick_results has one budget
    assert publish(quick_results, snap) >= 8
    assert (snap / "table1.csv").read_bytes() == (quick_results / "table1.csv").read_bytes()
    assert not (snap / "figure_budget.png").exists()


def test_bad_input_leaves_no_lock_or_temporary_file(tmp_path, capsys):
    renders = tmp_path / "renders"
    assert main(["render", "table", "--seed", "-1", "--renders", str(renders)]) == 2
    assert "seed must be a non-negative integer" in capsys.readouterr().err
    assert not renders.exists() or not any(renders.iterdir())
    results = tmp_path / "results"
    assert main(["run", "--seeds", "-2", "--results", str(results)]) == 2
    assert not results.exists()


def test_a_rerun_that_does_nothing_keeps_the_manifest_timings(quick_results, renders_dir, tmp_path):
    shutil.copytree(quick_results, tmp_path / "r")
    first = json.loads((tmp_path / "r" / "manifest.json").read_text())
    bench_run(SMALL, tmp_path / "r", renders_dir)  # every row done
    again = json.loads((tmp_path / "r" / "manifest.json").read_text())
    assert again["seconds"] == first["seconds"] and again["seconds"]["total"] > 0
    (inv,) = again["invocations"]
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert inv["rows"] == inv["rows_now"] == ROWS and set(runs["invocation"]) == {inv["id"]}


def test_the_manifest_names_whichever_distribution_provides_a_module(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """OpenCV from another distribution, pycolmap from none: the run still ends well."""
    from importlib.metadata import PackageNotFoundError, packages_distributions, version

    provided = {**packages_distributions(), "cv2": ["opencv-python-headless"]}
    del provided["pycolmap"]

    def installed(name):
        if name == "opencv-python-headless":
            return "5.0.0.1"
        if name in ("opencv-contrib-python-headless", "pycolmap"):
            raise PackageNotFoundError(name)
        return version(name)

    monkeypatch.setattr(harness, "packages_distributions", lambda: provided, raising=False)
    monkeypatch.setattr(harness, "version", installed)
    shutil.copytree(quick_results, tmp_path / "r")
    bench_run(SMALL, tmp_path / "r", renders_dir)
    versions = json.loads((tmp_path / "r" / "manifest.json").read_text())["versions"]
    assert versions["cv2"] == "opencv-python-headless 5.0.0.1"
    assert versions["pycolmap"] == "unknown" and versions["numpy"] == version("numpy")


def test_figures_state_nothing_impossible(quick_results, tmp_path, renders_dir, monkeypatch):
    runs = read_runs(quick_results / "runs.csv")
    t1 = pd.read_csv(quick_results / "table1.csv")
    for m in ("acc_completeness_pct", "accuracy_pct", "coverage_pct", "inlier_pct"):
        assert (t1[f"{m}_lo"].dropna() >= 0).all() and (t1[f"{m}_hi"].dropna() <= 100).all()
    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.__setitem__(out.name, fig))
    (tmp_path / "figure2.png").write_bytes(b"an older figure")
    shutil.copy(quick_results / "vocabulary.json", tmp_path)
    budgeted = runs[runs["budget"] > 0]
    write_report(pd.concat([runs, budgeted.assign(budget=128)]), tmp_path, renders_dir)
    assert not (tmp_path / "figure2.png").exists()  # not drawable here: removed, not stale
    ticks = [t.get_text() for t in drawn["figure_budget"].axes[0].get_xticklabels()]
    assert ticks == ["64", "128"]
    texts = [t.get_text() for ax in drawn["figure3"].axes for t in ax.texts]
    assert "n/a" in texts  # the peers have no known-pose metrics: drawn as missing


def test_written_files_respect_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        entry = render.render_scene("table", 3, TINY, tmp_path)
        cams, X = synthetic_rig()
        export_model(
            known_pose_model(
                cams, [f"v{k}.png" for k in range(4)], [c.project(X)[0] for c in cams]
            ),
            tmp_path / "m",
        )
    finally:
        os.umask(old)
    for p in (entry, tmp_path / "m"):
        assert stat.S_IMODE(p.stat().st_mode) == 0o755, p
    assert stat.S_IMODE((entry / "meta.json").stat().st_mode) == 0o644


# --- execution on Dask (issue 14) --------------------------------------------------------

PARALLEL = dataclasses.replace(
    SMALL, scenes=("table",), methods=("texture", "adaptive", "oracle", "colmap-b")
)


def test_two_dask_workers_give_the_same_metrics_as_one_process(renders_dir, tmp_path):
    one = bench_run(PARALLEL, tmp_path / "one", renders_dir, workers=1)
    two = bench_run(PARALLEL, tmp_path / "two", renders_dir, workers=2)
    metrics = [c for c in one.columns if c not in TIMING]
    pd.testing.assert_frame_equal(
        one[metrics].sort_values(list(KEY), ignore_index=True),
        two[metrics].sort_values(list(KEY), ignore_index=True),
    )


def test_a_unit_failing_on_a_worker_is_retried_once_then_recorded(
    renders_dir, tmp_path, monkeypatch
):
    from distributed import LocalCluster

    calls = []
    real = execute.predict

    def flaky(scene, unit, *a):
        calls.append(unit.method)
        if unit.method == "texture":
            raise RuntimeError("worker lost")
        return real(scene, unit, *a)

    monkeypatch.setattr(execute, "predict", flaky)
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        bench_run(PARALLEL, tmp_path, renders_dir, scheduler=cluster.scheduler_address)
    assert calls.count("texture") == 2  # tried, then retried once
    runs = read_runs(tmp_path / "runs.csv")
    failed = runs[runs["method"] == "texture"]
    assert len(failed) == 6 and (failed["status"] == "failed").all()
    assert failed["failure"].str.contains("retried once: RuntimeError: worker lost").all()
    assert (runs.loc[runs["method"] != "texture", "status"] == "ok").any()


def test_a_raising_policy_on_workers_is_one_line_without_retry_or_traceback(tmp_path, capfd):
    module = tmp_path / "boom.py"
    calls = tmp_path / "calls.txt"
    module.write_text(
        "from bench.frontend.policies import policy\n\n"
        "@policy('boom')\n"
        "def boom(inp, budget, rng, cfg):\n"
        f"    open({str(calls)!r}, 'a').write('call\\n')\n"
        "    raise ValueError('deterministic')\n"
    )
    argv = ["run", "--quick", "--scenes", "table", "--methods", "boom", "--workers", "2"]
    argv += ["--policy-module", str(module), "--tasks", "tri", "--protocols", "multiview"]
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(tmp_path)]) == 2
    err = capfd.readouterr().err
    assert "policy boom failed: ValueError: deterministic" in err and "Traceback" not in err
    assert len(calls.read_text().splitlines()) == 1  # the first view raised; no retry


@pytest.mark.parametrize(
    "sig, code, said", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")]
)
def test_a_signal_to_the_process_group_with_workers_stops_in_a_few_lines(
    renders_dir, tmp_path, sig, code, said
):
    """Ctrl-C (a terminal) and SIGTERM (`timeout`, systemd) reach the whole process group,
    workers included. SIGTERM printed each worker's native stack (glog's failure handler,
    which pycolmap installs: 62 lines, two dumps interleaved); now one line, as Ctrl-C."""
    import signal
    import subprocess
    import sys
    import time

    cmd = [sys.executable, "-m", "bench", "run", "--quick", "--scenes", "table", "--workers", "2"]
    cmd += ["--results", str(tmp_path / "r"), "--renders", str(renders_dir)]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (tmp_path / "r" / "runs.csv").exists() and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.1)
    os.killpg(proc.pid, getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    lines = err.strip().splitlines()
    assert proc.returncode == code, err
    assert lines[-1] == f"bench: {said}; finished work is kept", err
    assert all(line.startswith("bench: ") for line in lines), err  # no stack, no warning
    assert len(read_runs(tmp_path / "r" / "runs.csv")) >= 1  # the rows computed are kept


def test_the_readme_synopsis_names_every_option_of_every_command():
    import argparse
    import re

    from bench import ROOT

    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index("bench scenes  ") :]
    block = block[: block.index("```")]
    synopsis: dict[str, str] = {}
    for line in block.splitlines():
        if line.startswith("bench "):
            command = line.split()[1]
        synopsis[command] = synopsis.get(command, "") + line
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(synopsis)
    for command, parser in sub.choices.items():
        options = {o for a in parser._actions for o in a.option_strings if o.startswith("--")}
        missing = options - {"--help"} - set(re.findall(r"--[a-z-]+", synopsis[command]))
        assert not missing, f"bench {command}: {sorted(missing)} not in the README synopsis"


def test_a_results_folder_that_cannot_be_written_is_one_line(tmp_path, capsys):
    (tmp_path / "file").write_text("not a folder")
    argv = ["run", "--quick", "--scenes", "table", "--results", str(tmp_path / "file" / "r")]
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1
    assert f"{tmp_path / 'file'} in {tmp_path / 'file' / 'r'} is a file; give a folder" in err[0]


def test_images_without_any_candidate_are_named_not_a_budget_of_0(tmp_path, capsys):
    argv = ["run", "--scenes", "table", "--seeds", "0", "--width", "8", "--height", "6"]
    argv += ["--spp", "1", "--budget", "1", "--workers", "1", "--renders", str(tmp_path)]
    assert main([*argv, "--results", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "found no candidate in any view of table seed 0" in err and "up to 0" not in err


def test_a_twoview_only_run_prints_its_table_and_sfm_only_rows_name_figure2s_task(
    quick_results, tmp_path, renders_dir, capsys
):
    argv = ["run", "--scenes", "table", "--seeds", "0", "--budget", "64", "--workers", "1"]
    argv += ["--methods", "texture", "--protocols", "twoview", "--width", "320"]
    argv += ["--height", "240", "--spp", "16", "--max-depth", "2"]
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(renders_dir)]) == 0
    out = capsys.readouterr().out
    assert "Table 1 (twoview protocol" in out and "Empty DataFrame" not in out
    runs = read_runs(quick_results / "runs.csv")
    (tmp_path / "s").mkdir()
    shutil.copy(quick_results / "vocabulary.json", tmp_path / "s")
    write_report(runs[runs["task"] == "sfm"], tmp_path / "s", renders_dir)
    err = capsys.readouterr().err
    assert "figure2.png not drawn" in err and "known-pose (tri) task" in err


def test_the_budget_figure_says_n_a_for_a_panel_without_values(monkeypatch, tmp_path):
    from bench.report.tables import table1

    t1 = table1(
        pd.DataFrame(
            {
                "scene": "table",
                "seed": 0,
                "method": "texture",
                "budget": [64, 128],
                "status": "ok",
                "acc_completeness_pct": [1.0, 2.0],
                "completeness_vs_oracle_pct": math.nan,  # no oracle ran
            }
        ),
        Vocabulary.current(),
    )
    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.update(fig=fig))
    figures.figure_budget(t1, Vocabulary.current(), tmp_path / "figure_budget")
    texts = {
        ax.get_title(): [t.get_text() for t in ax.texts]
        for ax in drawn["fig"].axes
        if ax.get_visible()
    }
    oracle = next(k for k in texts if "oracle" in k)
    assert texts[oracle] == ["n/a: no run has this value"]
    assert all(not v for k, v in texts.items() if k != oracle)


def test_a_policy_module_decides_its_own_rows_only(renders_dir, tmp_path, monkeypatch):
    """A module's path is not bound into the folder (running without it is not refused),
    and editing it recomputes its policy's rows alone, not the built-in policies'."""
    module = tmp_path / "mine.py"
    source = (
        "import numpy as np\nfrom bench.frontend.policies import policy\n\n"
        "@policy('mine-{v}')\ndef mine(inp, budget, rng, cfg):\n"
        "    return np.arange(min(budget, len(inp.candidates)))\n"
    )
    module.write_text(source.format(v=1))
    grid = dict(scenes=("table",), seeds=(0,), budgets=(64,), tasks=("tri",))
    grid |= dict(protocols=("multiview",))

    def cfg(policies, modules=()):
        run = RunConfig(render=MEDIUM, policy=dataclasses.replace(PolicyConfig(), modules=modules))
        return BenchConfig(methods=policies, run=run, **grid)

    calls = []
    spy(monkeypatch, calls, lambda unit: unit.method)
    results = tmp_path / "r"
    bench_run(cfg(("texture", "mine-1"), (str(module),)), results, renders_dir)
    assert sorted(calls) == ["mine-1", "texture"]
    calls.clear()
    bench_run(cfg(("texture",)), results, renders_dir)  # without the module: not refused
    assert calls == [] and set(read_runs(results / "runs.csv")["method"]) == {"texture", "mine-1"}
    module.write_text(source.format(v=1).replace("np.arange(", "1 + np.arange("))
    plugins.load_module.cache_clear()
    registry.POLICIES.pop("mine-1")
    vocabulary.METHODS.pop("mine-1")
    bench_run(cfg(("texture", "mine-1"), (str(module),)), results, renders_dir)
    assert calls == ["mine-1"]  # the edited module's rows alone


# --- the architecture: one vocabulary, a report that reads results only ---------------


def test_plot_and_publish_run_without_colmap_opencv_or_mitsuba(quick_results, tmp_path):
    """The report stage reads results only: with pycolmap, cv2, mitsuba and drjit made
    unimportable, `bench plot` rewrites every table and figure (Figure 2 included) and
    `bench publish` copies them."""
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
        "assert not {'pycolmap', 'cv2', 'mitsuba', 'drjit', 'scipy.spatial'} & {"
        "m for m, v in sys.modules.items() if v is not None}\n"
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
    from bench.harness import tasks

    def count_points(truth, model, names, protocol, poses):
        return {"observed_points": 0 if model is None else model.num_points3D()}

    vocabulary.declare_metric(vocabulary.Metric("observed_points"))
    runner = tasks.TaskRunner(
        vocabulary.Task("count", "rig", needs=("observed_points",), metrics=("observed_points",)),
        reconstruct=lambda m, cfg, protocol: known_pose_task(
            m.image_dir, m.cams, m.names, m.xy, m.pairs, cfg, protocol
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
        del tasks.RUNNERS["count"], vocabulary.TASKS["count"], vocabulary.METRICS["observed_points"]
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
        ("backend.matcher=lightglue", "lightglue needs a pool with LightGlue weights"),
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
    from bench.harness.config import RunConfig

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
