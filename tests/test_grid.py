"""`bench run` and `bench plot` over a small grid: the files, resumption, what is computed
again and what is not, the configuration guard, reproducibility, bad input in one line."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
import pytest

from bench import BenchError, vocabulary
from bench.cli import main
from bench.harness import execute, keys
from bench.harness import grid as harness
from bench.render import entry as render
from bench.report.write import write_report
from bench.results import Workspace
from bench.runs import read_runs
from bench.unit.config import RunConfig
from bench.vocabulary import KEY, Job, Unit
from tests.conftest import (
    MEDIUM,
    POLICIES,
    ROWS,
    TIMING,
    bench_run,
    small_grid,
    spy,
)

SMALL = small_grid()


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
        (t, p) for t in ("tri", "sfm") for p in ("multiview", "twoview")
    } | {("pairs", "none")}  # pairs has no tracks: one row per unit
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
    (invocation,) = manifest["invocations"]
    assert invocation["cluster"] == {"workers": 1, "cores": os.cpu_count()}
    wall = invocation["wall"]
    assert set(wall) == {"render", "runs", "report", "total"} and wall == manifest["wall"]
    assert 0 < wall["render"] + wall["runs"] + wall["report"] <= wall["total"]
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


@pytest.fixture(scope="module")
def resumed(renders_dir, tmp_path_factory):
    """The small grid interrupted after three units, resumed, then run once more: the
    folder, and what each of the three invocations did (read by the tests below)."""
    folder, seen = tmp_path_factory.mktemp("resumed"), {}
    calls = []
    real = execute.predict

    def interrupt_after_three(scene, unit, *args):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(unit)
        return real(scene, unit, *args)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(execute, "predict", interrupt_after_three)
        with pytest.raises(KeyboardInterrupt):
            bench_run(SMALL, folder, renders_dir)
        seen["interrupted_rows"] = len(pd.read_csv(folder / "runs.csv"))
        seen["killed"] = json.loads((folder / "manifest.json").read_text())["invocations"]
        monkeypatch.setattr(execute, "predict", real)
        calls.clear()
        spy(monkeypatch, calls)
        bench_run(SMALL, folder, renders_dir)
        seen["resumed_calls"] = list(calls)
        seen["runs"] = pd.read_csv(folder / "runs.csv")
        seen["manifest"] = json.loads((folder / "manifest.json").read_text())
        calls.clear()
        rendered = []
        monkeypatch.setattr(harness, "render_scene", lambda *a, **k: rendered.append(a))
        bench_run(SMALL, folder, renders_dir)  # all done: nothing rendered, nothing run
        seen["done_calls"], seen["rendered"] = list(calls), rendered
    return folder, seen


def test_same_command_gives_identical_metrics(quick_results, resumed):
    """The grid once more (interrupted and resumed) gives the metrics of its first run."""
    a, b = (pd.read_csv(d / "runs.csv") for d in (quick_results, resumed[0]))
    metrics = [c for c in a.columns if c not in TIMING]
    pd.testing.assert_frame_equal(a[metrics], b[metrics])


def test_interrupted_run_resumes_without_redoing_rows(resumed):
    _, seen = resumed
    assert seen["interrupted_rows"] == 3 * 5  # tri, sfm x protocols; pairs
    # the interrupted invocation is in the manifest with its rows and seconds (it was not:
    # after a resume the page said frontend 0 and listed the resuming invocation alone)
    killed = seen["killed"]
    assert [(i["rows_now"], i["interrupted"]) for i in killed] == [(15, True)]
    assert killed[0]["seconds"]["frontend"] > 0
    assert len(seen["resumed_calls"]) == 2 * 8 - 3  # every unit of both scenes, but the three
    runs = seen["runs"]
    assert len(runs) == ROWS and not runs.duplicated(list(KEY)).any()
    manifest = seen["manifest"]
    both = manifest["invocations"]
    assert [i["id"] for i in both[:1]] == [killed[0]["id"]] and len(both) == 2
    assert sum(i["rows_now"] for i in both) == ROWS
    assert manifest["seconds"]["frontend"] == pytest.approx(
        sum(i["seconds"]["frontend"] for i in both)
    )
    assert seen["done_calls"] == [] and seen["rendered"] == []


def test_growing_a_results_folder_runs_only_the_new_rows(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """A new budget needs no --overwrite and runs only its rows; a changed setting
    is refused, naming the setting."""
    shutil.copytree(quick_results, tmp_path / "r")
    calls = []
    spy(monkeypatch, calls)
    # a budgeted selection and peer, and the two methods of budget 0, which it leaves
    some = ("texture", "colmap-b", "all", "colmap")
    grown = dataclasses.replace(SMALL, scenes=("table",), methods=some, budgets=(64, 32))
    bench_run(grown, tmp_path / "r", renders_dir)
    assert sorted(calls) == [("colmap-b", 32), ("texture", 32)]
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert len(runs) == ROWS + 5 + 3  # the new budget's selection and its colmap-b
    other = dataclasses.replace(SMALL, run=RunConfig(render=dataclasses.replace(MEDIUM, spp=4)))
    with pytest.raises(BenchError, match=r"other settings \(render.spp: 16 there, 4 now\)"):
        bench_run(other, tmp_path / "r", renders_dir)
    assert len(pd.read_csv(tmp_path / "r" / "runs.csv")) == len(runs)  # nothing lost


def test_rows_computed_by_other_code_are_computed_again(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """The key that decides whether a row is finished covers the stages' code."""
    shutil.copytree(quick_results, tmp_path / "r")
    monkeypatch.setattr(keys, "code_hash", lambda modules: "another-code")
    calls = []
    spy(monkeypatch, calls)
    some = ("texture", "colmap-b")  # a selection and a peer
    bench_run(
        dataclasses.replace(SMALL, scenes=("table",), methods=some), tmp_path / "r", renders_dir
    )
    assert sorted(calls) == [("colmap-b", 64), ("texture", 64)]  # every unit, again
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert len(runs) == 5 + 3  # one hash per method and task: their code and settings
    assert set(runs["scene"]) == {"table"} and set(runs["method"]) == set(some)
    assert runs.groupby(["method", "task"])["prediction_hash"].nunique().max() == 1


def test_rows_on_other_pixels_are_refused_and_rows_without_pixels_computed_again(
    quick_results, renders_dir, tmp_path, monkeypatch, capsys
):
    """A row names the pixels its unit read: rows of the same render key on other pixels
    (another machine's renders) are refused in one line naming both hashes, nothing
    computed; rows that name none (older folders) are computed again, never trusted; and
    a folder that mixes two pixels of one scene is refused by every reader."""
    from bench.runs import ROW_CHECKSUM, row_checksum

    folder = tmp_path / "r"
    shutil.copytree(quick_results, folder)
    runs = pd.read_csv(folder / "runs.csv", dtype=str, keep_default_na=False)
    mine, original = runs["pixels"].iloc[0], runs["pixels"].tolist()
    assert mine.startswith("px-") and runs.groupby("scene")["pixels"].nunique().max() == 1

    def rewrite(pixels):
        runs["pixels"] = pixels
        runs[ROW_CHECKSUM] = [row_checksum(r) for r in runs.to_dict("records")]
        runs.to_csv(folder / "runs.csv", index=False)

    rewrite(["px-elsewhere"] * len(runs))
    calls = []
    spy(monkeypatch, calls)
    with pytest.raises(BenchError, match=r"read pixels px-elsewhere, and its entry here has px-"):
        bench_run(SMALL, folder, renders_dir)
    assert calls == []
    first = runs["method"] == runs["method"].iloc[0]
    rewrite(["px-elsewhere" if f else mine for f in first])
    with pytest.raises(BenchError, match=r"mixes rows of \w+ seed 0 read from different pixels"):
        read_runs(folder / "runs.csv")
    rewrite(["" if f else mine for f in first])
    with pytest.raises(BenchError, match="unrecorded"):
        read_runs(folder / "runs.csv")
    table = (runs["scene"] == "table").tolist()
    rewrite(["" if t else px for t, px in zip(table, original)])  # one scene's rows name none
    again = bench_run(SMALL, folder, renders_dir)
    assert len(calls) == 8 and (again["pixels"].str.startswith("px-")).all()
    assert "name no pixels" in capsys.readouterr().err
    facade = again["scene"] == "facade"  # the other scene's rows kept, not computed again
    assert len(again) == ROWS and facade.sum() == ROWS // 2
    assert set(again.loc[facade, "pixels"]) == {px for t, px in zip(table, original) if not t}
    assert set(again.loc[facade, "invocation"]) == set(
        runs["invocation"][runs["scene"] == "facade"]
    )


def test_a_changed_scene_is_computed_again_and_no_other(
    quick_results, renders_dir, tmp_path, monkeypatch, capsys
):
    """A row records the render entry it was computed on: a scene whose generator,
    parameters or render settings changed since (here its render key) is rendered and
    computed again; the other scene's rows are kept as they are."""
    shutil.copytree(quick_results, tmp_path / "r")
    real = render._pixel_fields
    monkeypatch.setattr(
        render,
        "_pixel_fields",
        lambda spec, *a: real(spec, *a) | ({"edited": 1} if spec.name == "table" else {}),
    )
    calls = []
    spy(monkeypatch, calls, what=lambda unit: unit.scene)
    one = dataclasses.replace(SMALL, methods=("texture",))  # a unit of each scene shows it
    runs = bench_run(one, tmp_path / "r", renders_dir)
    assert calls == ["table"]
    assert "the scene table (its generator, parameters or render settings) changed" in (
        capsys.readouterr().err
    )
    before = read_runs(quick_results / "runs.csv").set_index(list(KEY))["render_key"]
    after = runs.set_index(list(KEY))["render_key"].reindex(before.index)
    table = before.index.get_level_values("scene") == "table"
    texture = table & (before.index.get_level_values("method") == "texture")
    assert after[texture].notna().all() and (after[texture] != before[texture]).all()
    assert (after[~table] == before[~table]).all()


def test_a_changed_metric_rescores_the_stored_predictions_alone(
    quick_results, renders_dir, tmp_path, monkeypatch
):
    """Scores apart from predictions: a new evaluation hash (a metric edited), or
    --reevaluate, scores every row again from the stored predictions without selecting,
    matching or mapping, and gives the same metrics."""
    shutil.copytree(quick_results, tmp_path / "r")
    calls = []
    spy(monkeypatch, calls)
    monkeypatch.setattr(keys, "evaluation_hash", lambda: "another-metric")
    monkeypatch.setattr(harness, "evaluation_hash", lambda: "another-metric")
    table = dataclasses.replace(SMALL, scenes=("table",))  # every method and task: one scene
    again = bench_run(table, tmp_path / "r", renders_dir)
    assert calls == [] and set(again["evaluation_hash"]) == {"another-metric"}
    before = read_runs(quick_results / "runs.csv")
    before = before[before["scene"] == "table"].reset_index(drop=True)
    assert len(again) == len(before) == ROWS // 2
    metrics = [c for c in before.columns if c not in TIMING and c != "evaluation_hash"]
    pd.testing.assert_frame_equal(before[metrics], again[metrics])
    shutil.rmtree(tmp_path / "r" / "models" / "table-s0" / "texture-b64")  # its prediction lost
    bench_run(table, tmp_path / "r", renders_dir, reevaluate=True)
    assert calls == [("texture", 64)]  # predicted again; every other row scored alone


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
        (["run", "--budget", "0"], "--budget takes keypoints per view, each at least 1, got 0"),
        (["run", "--budget", "12x"], "--budget takes one comma-separated list"),
        (["run", "--budget", "128,,256"], "e.g. --budget 128,256,512"),
        (["run", "--scenes", "table", "facade"], "list options take one comma-separated list"),
        (["run", "--seeds", "-1"], "seeds must be non-negative integers"),
        (["run", "--scenes", "moon"], "unknown scene 'moon'"),
        (["run", "--detector", "surf"], "unknown detector 'surf'; valid: sift"),
        (["run", "--weights", "0.3,x,0,0,0"], "is not a list of float"),
        (["run", "--weights", "0.3,0.2"], "weights must be five numbers"),
        (["run", "--seeds", "3-1"], "the range 3-1 is empty (write it low-high)"),
        (["run", "--scenes", ""], "--scenes takes one comma-separated list"),  # ran all four
        (["run", "--seeds", ""], "--seeds takes one comma-separated list"),
        (["run", "--dataset", "/nonexistent/set"], "/nonexistent/set does not exist"),
        (["run", "--policy-module", "examples"], "--policy-module examples is a directory"),
        (["train-weights", "--seeds", "5-3"], "the range 5-3 is empty"),
        (["run", "--scheduler", "x:1", "--workers", "2"], "--workers does not apply"),
        (["run", "--scheduler", "notanaddress"], "cannot reach the Dask scheduler notanaddress"),
        (["run", "--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler tcp://"),
    ],
)
def test_run_bad_input_is_one_clear_line(argv, message, tmp_path, capsys, monkeypatch):
    import distributed.comm

    # a refused port is tried again until the connect timeout (10 s): 1 s tells the same
    real = distributed.comm.connect
    monkeypatch.setattr(distributed.comm, "connect", lambda a, timeout: real(a, timeout="1s"))
    where = ["--results", str(tmp_path / "r")] if argv[0] == "run" else []
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main([*argv, *where]))
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["render", "table", "--views", "100000"], "views must be from 2 to 256, got 100000"),
        (["render", "moon"], "unknown scene 'moon'"),  # was after the render variant's line
        (["export", "table", "--out", "{tmp}/mine"], "exists and is not an earlier export"),
        (["upgrade", "--results", "{tmp}/missing"], "missing not found: give a results folder"),
    ],
)
def test_refused_before_any_work_in_one_line(argv, message, tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine\n")
    argv = [a.format(tmp=tmp_path) for a in argv] + ["--renders", str(tmp_path / "renders")]
    if argv[0] == "upgrade":
        argv = argv[:-2]
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main(argv))
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "renders").exists() and not (tmp_path / "missing").exists()


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


def test_one_version_in_the_package_and_the_changelog_and_none_in_the_readme(capsys):
    """`bench --version` said 0.2.0 (pyproject.toml too) where the README and CHANGELOG
    said 0.4.0: pyproject.toml is the one source, read from the installed metadata; the
    version history is the CHANGELOG's, not the README's."""
    import re
    import tomllib

    from bench import ROOT, __version__

    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.split()[1] == __version__
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    newest = re.search(r"^## (\S+)", (ROOT / "CHANGELOG.md").read_text(), re.M).group(1)
    assert project["version"] == newest
    assert not re.search(r"\b\d+\.\d+\.\d+\b|issue \d", (ROOT / "README.md").read_text())


# --- statistics -----------------------------------------------------------------------


def test_cells_stock_colmap_cannot_map_are_marked_and_left_out_of_the_sfm_means():
    from bench.report.tables import headline_frame, paired_sfm, table1, table_scenes
    from bench.runs import mark_reference

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
    from bench.runs import mark_reference

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


def test_a_budget_above_every_pool_is_refused_in_one_line(renders_dir, tmp_path, capsys):
    # the tiny render of the raising-plugin tests (test_failures), kept in the session's renders
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
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(renders_dir)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "budget 100000 exceeds every candidate pool of table seed 0" in err[-1]
    assert not (tmp_path / "r").exists()  # a refused run binds no folder to its settings
    other = ["--budget", "16", "--spp", "3", "--methods", "texture", "--tasks", "tri"]
    argv = [*argv[:5], *argv[7:], "--protocols", "multiview"]  # the same, less the budget
    where = ["--results", str(tmp_path / "r"), "--renders", str(renders_dir)]
    assert main([*argv, *other, *where]) == 0
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


def _tiny_dataset(folder: Path) -> Path:
    """Three 64x48 noise images and their rig: a dataset in the COLMAP layout."""
    import cv2

    from bench.camera import Camera, write_colmap_rig

    (folder / "images").mkdir(parents=True)
    (folder / "sparse").mkdir()
    names = [f"v{k}.png" for k in range(3)]
    rng = np.random.default_rng(0)
    for n in names:
        cv2.imwrite(str(folder / "images" / n), rng.integers(0, 255, (48, 64, 3), np.uint8))
    cam = Camera(64, 48, 50.0, 50.0, 32.0, 24.0, np.eye(3), np.zeros(3))
    write_colmap_rig([cam] * 3, folder / "sparse", names)
    return folder


def test_a_dataset_runs_options_are_checked_before_any_work(tmp_path, capsys):
    """`--rendered /missing` ran the whole grid and exited 0; a repeated `--dataset` and
    too few methods for a ranking ended in "share no ranked budget"."""
    d = str(_tiny_dataset(tmp_path / "set"))
    where = ["--results", str(tmp_path / "r"), "--renders", str(tmp_path / "renders")]
    argv = ["run", "--dataset", d, "--rendered", str(tmp_path / "missing"), *where]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"bench: error: --rendered {tmp_path / 'missing'}: no runs.csv there; "
        "give a rendered results folder of `bench run`"
    ]
    argv = ["run", "--dataset", d, "--dataset", d, "--methods", "texture,adaptive"]
    assert main([*argv, "--budget", "0", *where]) == 2
    err = capsys.readouterr().err
    assert "--dataset repeats set; each runs once" in err
    assert "transfer.csv will hold no tau: --methods gives 2 budgeted method(s) (texture, " in err
    assert not (tmp_path / "r").exists() and not (tmp_path / "renders").exists()


def test_no_transfer_says_what_the_two_sides_share():
    from bench.report.transfer import why_none

    published = Path(__file__).resolve().parents[1] / "results" / "published"
    rows = pd.DataFrame({"method": ["texture", "adaptive", "all"], "budget": [256, 256, 0]})
    assert why_none(rows, [published]) == (
        "at most 2 budgeted method(s) at one budget (adaptive, texture at 256); a ranking "
        "needs at least 3 methods, and a tau at least 6"
    )
    assert why_none(rows.assign(budget=64), [published]).startswith(
        "no budget (the datasets ran 64; the rendered results 128, 256, 512)"
    )


def test_a_dataset_run_into_a_rendered_grids_folder_is_refused_for_that_reason(tmp_path):
    """It named `nbv.between`, the first setting in sort order that differed."""
    from bench.binding import check_results_dir

    rendered = {"render": {"views": 6}, "nbv": {"between": 3}, "backend": {"ratio": 0.8}}
    (tmp_path / "config.json").write_text(json.dumps({"settings": rendered}))
    dataset = {"render": None, "nbv": {"between": 0}, "backend": {"ratio": 0.8}}
    with pytest.raises(
        BenchError,
        match="holds a grid of rendered scenes, and this run is on "
        "datasets; give another --results folder",
    ):
        check_results_dir(tmp_path, dataset, overwrite=False)


def test_select_lists_only_the_policies_it_runs(tmp_path, capsys):
    images = str(_tiny_dataset(tmp_path / "set") / "images")
    for policy, what in (("nope", "is unknown"), ("colmap-b", "is a method bench select cannot")):
        assert (
            main(["select", "--images", images, "--out", str(tmp_path / "o"), "--policy", policy])
            == 2
        )
        (err,) = capsys.readouterr().err.strip().splitlines()
        assert f"--policy {policy!r} {what}" in err and "adaptive" in err
        valid = err.split("valid: ")[1].split(", ")
        assert "colmap-b" not in valid and "random-view" not in valid and "oracle" not in valid


def test_the_transfer_hint_counts_the_methods_as_placed_on_the_pools(tmp_path, capsys):
    """Three methods on three pools rank seven: no "will hold no tau" line, which counted
    the names given to --methods."""
    d = str(_tiny_dataset(tmp_path / "set"))
    where = ["--results", str(tmp_path / "r"), "--renders", str(tmp_path / "renders")]
    argv = ["run", "--dataset", d, "--methods", "texture,grid,random", "--budget", "0", *where]
    assert main(argv) == 2  # refused later, for its budget
    assert "will hold no tau: --methods gives 3 budgeted method(s)" in capsys.readouterr().err
    assert main([*argv, "--pools", "sift,orb"]) == 2
    assert "will hold no tau" not in capsys.readouterr().err
