"""Results that cannot be altered unseen: rows that carry their own checksum and ranges,
`runs.csv` appended as units finish, `bench publish` that keeps a snapshot of other
settings, `bench plot` and `bench publish` on a read-only or held folder."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from bench import ROOT, BenchError
from bench.backend.reconstruction import known_pose_model
from bench.cli import build_parser, common, main
from bench.cli.common import LATEST, QUICK, REGIMES, parse_list, regime_folder
from bench.harness import execute, manifest
from bench.harness.grid import BenchConfig
from bench.render import entry as render
from bench.report import figures
from bench.report.publish import publish
from bench.report.write import write_report
from bench.runs import read_runs
from bench.unit.config import RunConfig
from bench.unit.predict import export_model
from bench.vocabulary import KEY, Vocabulary
from tests.conftest import (
    MEDIUM,
    ROWS,
    TINY,
    bench_run,
    small_grid,
    synthetic_rig,
)

GRID = BenchConfig(
    scenes=("table",),
    seeds=(0,),
    methods=("texture", "grid"),
    budgets=(64,),
    tasks=("tri",),
    protocols=("multiview",),
    run=RunConfig(render=MEDIUM),
)
PUBLISHED = ROOT / "results" / "published"


@pytest.fixture(scope="module")
def small_run(renders_dir, tmp_path_factory):
    """A real run of two rows (texture and grid, tri, multiview, table seed 0)."""
    results = tmp_path_factory.mktemp("integrity") / "r"
    bench_run(GRID, results, renders_dir)
    return results


def _edit(runs_csv: Path, method: str, column: str, value: str, reseal: bool = False):
    """Set one value of `method`'s row of `runs.csv` in place, as a hand edit would
    (`reseal`: with the checksum recomputed, as a bug that wrote it would); (its line, the
    old value)."""
    rows = list(csv.reader(runs_csv.read_text().splitlines()))
    header = rows[0]
    line = next(n for n, row in enumerate(rows, 1) if row[header.index("method")] == method)
    row = rows[line - 1]
    old, row[header.index(column)] = row[header.index(column)], value
    if reseal:
        from bench.runs import row_checksum

        row[-1] = row_checksum(dict(zip(header, row)))
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows)
    runs_csv.write_text(out.getvalue())
    return line, old


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_hand_edited_metric_is_refused_by_plot_publish_and_a_resumed_run(
    small_run, renders_dir, tmp_path, capsys, monkeypatch
):
    """One metric changed by hand (26.28 -> 99.0 in the report that found it) was plotted,
    reused by a resumed run and published; now each refuses it in one line naming the file
    and the row, and `--reevaluate` scores it again from the stored prediction."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    before = (r / "table1.csv").read_bytes()
    line, old = _edit(r / "runs.csv", "grid", "acc_completeness_pct", "99.0")
    assert float(old) != 99.0
    where = (
        f"{r / 'runs.csv'} is damaged: row at line {line} (table, seed 0, grid, budget 64, tri, "
    )
    where += "multiview): its values do not match its row_checksum"
    assert main(["plot", "--results", str(r), "--renders", str(renders_dir)]) == 2
    said = _one_line(capsys)  # what is wrong and the remedy; plot publishes nothing anyway
    assert where in said and "published" not in said
    assert f"`bench run --reevaluate --results {r}` (with the grid it holds)" in said
    assert (r / "table1.csv").read_bytes() == before  # nothing rewritten from it
    assert main(["publish", "--results", str(r), "--to", str(tmp_path / "p")]) == 2
    assert where in _one_line(capsys) and not (tmp_path / "p" / "runs.csv").exists()
    assert main(["upgrade", "--results", str(r)]) == 2  # was "up to date; nothing changed", 0
    assert where in _one_line(capsys)
    with pytest.raises(BenchError, match="do not match its row_checksum") as e:
        bench_run(GRID, r, renders_dir)
    assert f"--reevaluate --results {r}` (with the grid it holds) scores altered" in str(e.value)
    predicted = []
    real = execute.predict
    monkeypatch.setattr(execute, "predict", lambda *a: predicted.append(a) or real(*a))
    rows = bench_run(GRID, r, renders_dir, reevaluate=True)
    assert predicted == []  # scored again from the stored prediction
    fixed = rows.set_index("method").loc["grid", "acc_completeness_pct"]
    assert fixed == pytest.approx(float(old)) and (r / "table1.csv").read_bytes() == before


def test_reevaluate_says_it_scores_rows_again_not_that_it_does_them(
    small_run, renders_dir, tmp_path, capsys
):
    """`--reevaluate` said "0 of 2 rows already in ...; 2 to do, 2 of them scored again"."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    bench_run(GRID, r, renders_dir, reevaluate=True)
    said = capsys.readouterr().err
    line = f"0 of 2 rows already in {r / 'runs.csv'}; 2 rows to score again from their stored "
    assert line + "predictions\n" in said and "to do" not in said
    bench_run(dataclasses.replace(GRID, methods=("texture", "grid", "random")), r, renders_dir)
    assert f"2 of 3 rows already in {r / 'runs.csv'}; 1 to compute\n" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["150", "-5"])
@pytest.mark.parametrize("reseal", [False, True])
def test_a_percentage_outside_0_to_100_is_refused(small_run, tmp_path, capsys, value, reseal):
    """Values of 150 and -5 for a percentage passed every check; now each is refused, also
    with a checksum that matches (a bug, not a hand edit)."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    line, _ = _edit(r / "runs.csv", "texture", "accuracy_pct", value, reseal)
    assert main(["plot", "--results", str(r)]) == 2
    err = _one_line(capsys)
    assert (
        f"{r / 'runs.csv'} is damaged: row at line {line} (table, seed 0, texture, budget 64" in err
    )
    assert f"accuracy_pct {value} is outside its range [0, 100]" in err


def test_a_computed_row_outside_its_range_is_never_written(tmp_path):
    from bench.runs import append_runs
    from bench.vocabulary import Vocabulary

    row = read_runs(PUBLISHED / "runs.csv").iloc[0].to_dict() | {"maa": 1.5}
    with pytest.raises(BenchError, match=r"breaks the runs.csv contract: maa 1.5 is outside"):
        append_runs(tmp_path / "runs.csv", [row], Vocabulary.current())
    assert not (tmp_path / "runs.csv").exists()


def test_runs_csv_is_appended_to_not_rewritten(small_run, renders_dir, tmp_path, monkeypatch):
    """A unit's rows are appended (the rows before them keep their bytes, the header is
    written once); a cut append is caught as damage and set aside on request."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    before = (r / "runs.csv").read_text()
    rewritten = []
    import bench.runs as runs

    real = runs.write_text_atomic
    monkeypatch.setattr(
        runs, "write_text_atomic", lambda p, t: rewritten.append(p.name) or real(p, t)
    )
    grown = dataclasses.replace(GRID, budgets=(64, 32))
    bench_run(grown, r, renders_dir)
    after = (r / "runs.csv").read_text()
    assert after.startswith(before) and len(after.splitlines()) == 5  # two rows added
    assert "runs.csv" not in rewritten and after.count("scene,seed") == 1
    lines = after.splitlines()
    (r / "runs.csv").write_text("\n".join([*lines[:-1], lines[-1][:-3]]) + "\n")  # a cut append
    with pytest.raises(BenchError, match="is damaged: row at line 5"):
        read_runs(r / "runs.csv")
    rows = bench_run(grown, r, renders_dir, set_aside=True)
    assert len(rows) == 4 and lines[-1][:-3] in (r / "runs.damaged.csv").read_text()


def test_publish_keeps_a_snapshot_of_other_settings_unless_replace(small_run, tmp_path, capsys):
    """Publishing 2 rows at 320x240 over the published snapshot replaced it (and deleted
    its budget figure) without a word; now it is refused naming the differences."""
    snap = tmp_path / "published"
    shutil.copytree(PUBLISHED, snap)
    argv = ["publish", "--results", str(small_run), "--to", str(snap)]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert f"{snap} holds a snapshot of other settings or another grid (" in err
    for phrase in (
        "render.width: 640 there, 320 here",
        "scene: corridor, facade, vegetation only there",
        "seed: 1, 2, 3, 4 only there",
        "task: pairs, sfm only there",
        "); --replace replaces it",
    ):
        assert phrase in err
    assert (snap / "runs.csv").read_bytes() == (PUBLISHED / "runs.csv").read_bytes()
    assert (snap / "figure_budget.png").is_file()
    assert main([*argv, "--replace"]) == 0
    assert (snap / "runs.csv").read_bytes() == (small_run / "runs.csv").read_bytes()
    assert main(argv) == 0  # the same settings and grid again: no --replace needed


def _errored(runs_csv: Path) -> None:
    """Mark the grid row of `runs.csv` as one that could not be computed (resealed)."""
    from bench.runs import ROW_CHECKSUM, append_runs
    from bench.vocabulary import REFERENCE_MAPS

    runs = read_runs(runs_csv)
    grid = runs["method"] == "grid"
    runs.loc[grid, "status"], runs.loc[grid, "failure"] = "failed", "error: policy grid raised"
    runs.loc[grid, ["acc_completeness_pct", "accuracy_pct", "rmse"]] = math.nan
    runs_csv.unlink()
    rows = runs.drop(columns=[ROW_CHECKSUM, REFERENCE_MAPS], errors="ignore").to_dict("records")
    append_runs(runs_csv, rows, Vocabulary.current())


@pytest.mark.parametrize(
    "damage, options, message",
    [
        (_errored, [], "is not published: 1 row(s) could not be computed, of grid (1)"),
        (lambda r: (r.parent / "table1.csv").unlink(), [], "has no table1.csv: `bench plot"),
        (lambda r: (r.parent / "README.md").unlink(), [], "has no README.md: `bench plot"),
        (
            lambda r: None,
            ["--regime", "dense"],
            "is not the dense regime's grid (scenes table, the regime's corridor, facade, "
            "table, vegetation; seeds 0, the regime's 0, 1; views 6, the regime's 21; render "
            "size 320x240, the regime's 640x480); publish a `bench run --regime dense` there",
        ),
    ],
)
def test_publish_refuses_what_it_should_not_publish_and_creates_nothing(
    small_run, tmp_path, capsys, damage, options, message
):
    """Rows that failed with errors, a folder without tables and a 320x240 run as `--regime
    dense` were published, and a refused publish left an empty folder behind."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    damage(r / "runs.csv")
    snap = tmp_path / "new" / "published"
    assert main(["publish", "--results", str(r), "--to", str(snap), *options]) == 2
    assert f"{r} {message}" in _one_line(capsys)
    assert not (tmp_path / "new").exists()


def test_publish_into_a_regimes_snapshot_checks_its_grid(small_run, tmp_path, capsys, monkeypatch):
    shutil.copytree(small_run, tmp_path / "results" / "latest")
    monkeypatch.chdir(tmp_path)
    assert main(["publish"]) == 2  # results/latest -> results/published: the sparse regime
    err = _one_line(capsys)
    assert "results/latest is not the sparse regime's grid (scenes table, the regime's" in err
    assert "seeds 0, the regime's 0, 1, 2, 3, 4; " in err and "views" not in err
    assert not (tmp_path / "results" / "published").exists()
    assert main(["publish", "--to", str(tmp_path / "mine")]) == 0  # a snapshot of its own
    said = capsys.readouterr().err  # and it says that it is no regime's grid
    assert "published as a snapshot of its own: results/latest's grid is checked" in said


def test_a_setting_added_since_the_snapshot_differs_only_off_its_default(
    small_run, tmp_path, capsys
):
    """A snapshot of the code before backend.matcher existed is published over without
    --replace when the new folder has it at its default (the behaviour before), not when it
    has another value."""
    snap, r = tmp_path / "published", tmp_path / "r"
    shutil.copytree(small_run, snap)
    shutil.copytree(small_run, r)
    old = json.loads((snap / "config.json").read_text())
    del old["settings"]["backend"]["matcher"]
    (snap / "config.json").write_text(json.dumps(old))
    argv = ["publish", "--results", str(r), "--to", str(snap)]
    assert main(argv) == 0
    assert "published as a snapshot of its own" in capsys.readouterr().err
    (snap / "config.json").write_text(json.dumps(old))
    new = json.loads((r / "config.json").read_text())
    new["settings"]["backend"]["matcher"] = "lightglue"
    (r / "config.json").write_text(json.dumps(new))
    assert main(argv) == 2
    assert "(backend.matcher: None there, 'lightglue' here); --replace" in _one_line(capsys)


def test_the_published_snapshot_carries_its_checksums():
    rows = read_runs(PUBLISHED / "runs.csv")
    written = json.loads((PUBLISHED / "manifest.json").read_text())["invocations"][-1]
    assert len(rows) == written["rows_now"] and rows["row_checksum"].str.len().eq(12).all()
    # derived on reading from its colmap rows: every view registered with mAA >= 0.5
    ref = rows[(rows["method"] == "colmap") & (rows["task"] == "sfm")]
    ref = ref[ref["protocol"] == "multiview"].set_index(["scene", "seed"])
    maps = (ref["registered_views"] == ref["views"]) & (ref["maa"] >= 0.5)
    cells = pd.MultiIndex.from_frame(rows[["scene", "seed"]])
    assert rows["reference_maps"].notna().all()
    assert (rows["reference_maps"].to_numpy() == maps.reindex(cells).astype(int).to_numpy()).all()


def _read_only(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    """Run `python argv` with `folder` mounted read-only (in a user and mount namespace:
    root writes through permission bits, not through a read-only mount)."""
    cmd = f'mount --bind -o ro "{folder}" "{folder}" && exec "$@"'
    return subprocess.run(
        ["unshare", "-rm", "sh", "-c", cmd, "sh", sys.executable, *argv],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )


def _can_mount_read_only(tmp_path: Path) -> bool:
    if shutil.which("unshare") is None:
        return False
    return _read_only(tmp_path, "-c", "").returncode == 0


def test_plot_and_publish_on_a_read_only_folder_are_one_line(small_run, tmp_path):
    """`bench plot` on a read-only folder ended in an OSError traceback (the clean-up of
    `atomic_path` failing in turn); now one line, and the clean-up never hides the error."""
    if not _can_mount_read_only(tmp_path):
        pytest.skip("no unshare with mount namespaces here")
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    done = _read_only(r, "-m", "bench", "plot", "--results", str(r))
    assert done.returncode == 2 and done.stderr.strip().count("\n") == 0, done.stderr
    assert f"cannot write to {r}: Read-only file system" in done.stderr
    snap = tmp_path / "snap"
    snap.mkdir()
    done = _read_only(snap, "-m", "bench", "publish", "--results", str(r), "--to", str(snap))
    assert done.returncode == 2 and done.stderr.strip().count("\n") == 0, done.stderr
    assert f"cannot write to {snap}: Read-only file system" in done.stderr
    done = _read_only(r, "-m", "bench", "publish", "--results", str(r), "--to", str(snap / "p"))
    assert done.returncode == 0, done.stderr  # a read-only folder is published from
    script = (
        "from bench.files import atomic_path\n"
        f"with atomic_path({str(r / 'table1.csv')!r}):\n"
        "    raise ValueError('the error that ended the block')\n"
    )
    done = _read_only(r, "-c", script)
    assert "ValueError: the error that ended the block" in done.stderr.splitlines()[-1]


@pytest.mark.parametrize("command", ["plot", "publish"])
def test_plot_and_publish_refuse_a_folder_a_run_holds(small_run, tmp_path, capsys, command):
    """`bench plot` read a folder a run was writing and rewrote the tables from partial
    rows; now plot and publish are refused while a run holds the folder."""
    from bench.files import exclusive

    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    before = (r / "table1.csv").read_bytes()
    argv = [command, "--results", str(r)]
    argv += ["--to", str(tmp_path / "p")] if command == "publish" else []
    with exclusive(r / ".bench-run.lock", "a run"):  # as `bench run` holds it
        assert main(argv) == 2
    assert f"results folder {r} is in use by another bench process" in _one_line(capsys)
    assert (r / "table1.csv").read_bytes() == before and not (tmp_path / "p" / "runs.csv").exists()
    assert main(argv) == 0  # released: done


def test_a_folder_written_before_checksums_is_refused_then_reevaluated(
    small_run, renders_dir, tmp_path, capsys
):
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    rows = list(csv.reader((r / "runs.csv").read_text().splitlines()))
    old = "\n".join(",".join(row[:-1]) for row in rows) + "\n"  # no row_checksum column
    (r / "runs.csv").write_text(old)
    assert main(["plot", "--results", str(r)]) == 2
    assert "was written before rows carried checksums; `bench run --reevaluate`" in _one_line(
        capsys
    )
    bench_run(GRID, r, renders_dir, reevaluate=True)
    assert len(read_runs(r / "runs.csv")) == 2
    assert json.loads((r / "config.json").read_text())["settings"]["render"]["width"] == 320


def test_a_folder_with_the_old_policy_column_is_refused_and_upgraded(small_run, tmp_path, capsys):
    """A `runs.csv` written before the column was named `method` (its rows sealed under the
    old name) is refused in one line naming `bench upgrade`, which renames the column and
    re-seals every row whose checksum held; a row altered by hand stays altered."""
    from bench.runs import ROW_CHECKSUM, row_checksum

    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    rows = list(csv.reader((r / "runs.csv").read_text().splitlines()))
    header = ["policy" if c == "method" else c for c in rows[0]]
    for row in rows[1:]:
        row[-1] = row_checksum(dict(zip(header, row)))
    rows[2][header.index("points")] = "1"  # altered after sealing
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows([header, *rows[1:]])
    (r / "runs.csv").write_text(out.getvalue())
    assert main(["plot", "--results", str(r)]) == 2
    assert _one_line(capsys).endswith(f"`bench upgrade --results {r}` renames it")
    assert main(["upgrade", "--results", str(r)]) == 2  # renamed, and the altered row said
    said = capsys.readouterr()
    assert "runs.csv: column policy renamed method (2 rows)" in said.out
    assert "line 3" in said.err and "do not match its row_checksum" in said.err
    new = list(csv.DictReader((r / "runs.csv").read_text().splitlines()))
    assert [row[ROW_CHECKSUM] == row_checksum(row) for row in new] == [True, False]
    with pytest.raises(BenchError, match="line 3 .*do not match its row_checksum"):
        read_runs(r / "runs.csv")


SMALL = small_grid()


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
    cut = _cut(r / "runs.csv", ROWS)  # the last row: one unit's job to compute again
    medium = ["--width", "320", "--height", "240", "--spp", "16", "--max-depth", "2"]
    grid = ["run", "--scenes", "table,facade", "--seeds", "0", "--budget", "64", *medium]
    for argv in (["plot"], grid):
        assert main([*argv, "--results", str(r), "--renders", str(renders_dir)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert f"{r / 'runs.csv'} is damaged: row at line {ROWS + 1}" in err[-1]
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
        assert common.PUBLISHED not in target.parents and target != common.PUBLISHED
    for regime in REGIMES:
        published = regime_folder(common.PUBLISHED, regime)
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


def test_publish_carries_a_photo_runs_transfer_and_per_set_tables(quick_results, tmp_path):
    """Published photo sets lacked `transfer.csv`, which the README's photo sentences read."""
    results, snap = tmp_path / "photos", tmp_path / "published-datasets"
    shutil.copytree(quick_results, results)
    for name in ("transfer.csv", "transfer_ranks.csv", "figure_transfer.png", "table1-a.csv"):
        (results / name).write_text(name)
    snap.mkdir()
    (snap / "table1-gone.csv").write_text("stale")
    publish(results, snap)
    for name in ("transfer.csv", "transfer_ranks.csv", "figure_transfer.png", "table1-a.csv"):
        assert (snap / name).read_text() == name
    assert not (snap / "table1-gone.csv").exists()


def test_bad_input_leaves_no_lock_or_temporary_file(tmp_path, capsys):
    renders = tmp_path / "renders"
    assert main(["render", "table", "--seed", "-1", "--renders", str(renders)]) == 2
    assert "seed must be a non-negative integer" in capsys.readouterr().err
    assert not renders.exists() or not any(renders.iterdir())
    results = tmp_path / "results"
    assert main(["run", "--seeds", "-2", "--results", str(results)]) == 2
    assert not results.exists()


def test_a_rerun_that_does_nothing_keeps_the_manifest_timings(small_run, renders_dir, tmp_path):
    shutil.copytree(small_run, tmp_path / "r")
    first = json.loads((tmp_path / "r" / "manifest.json").read_text())
    bench_run(GRID, tmp_path / "r", renders_dir)  # every row done
    again = json.loads((tmp_path / "r" / "manifest.json").read_text())
    assert again["seconds"] == first["seconds"] and again["seconds"]["total"] > 0
    (inv,) = again["invocations"]
    runs = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert inv["rows"] == inv["rows_now"] == 2 and set(runs["invocation"]) == {inv["id"]}


def test_the_manifest_names_whichever_distribution_provides_a_module(
    small_run, renders_dir, tmp_path, monkeypatch
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

    monkeypatch.setattr(manifest, "packages_distributions", lambda: provided, raising=False)
    monkeypatch.setattr(manifest, "version", installed)
    shutil.copytree(small_run, tmp_path / "r")
    bench_run(GRID, tmp_path / "r", renders_dir)
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


def _pairs_row(seed: int, protocol: str, task: str = "pairs") -> dict:
    """A hand-made `ok` row of one unit (table, seed, texture at 64)."""
    row = {"scene": "table", "seed": seed, "method": "texture", "budget": 64, "task": task}
    row |= {"protocol": protocol, "render_key": "r", "prediction_hash": "p"}
    row |= {"evaluation_hash": "e", "status": "ok", "failure": "", "invocation": "i"}
    if task == "tri":
        return row | {"wall_ms": 1.0, "points": 9, "acc_completeness_pct": 12.5}
    return row | {"wall_ms": 1.0, "auc_10": 0.5, "maa_pairs": 0.4, "pairs_scored": 15}


def test_pairs_rows_are_written_once_and_an_older_folders_twice_upgraded(tmp_path, capsys):
    """The pairs task has no tracks: an older bench wrote each unit's row once per track
    protocol, identical (a 50-unit run reported 100 rows); its folder is refused until `bench
    upgrade` keeps one row per unit, protocol none, its checksum valid. A row of the pairs
    task under a track protocol breaks the contract now."""
    from bench.runs import append_runs

    current = Vocabulary.current()
    with pytest.raises(BenchError, match="protocol 'multiview' in the pairs task .*'none'"):
        append_runs(tmp_path / "x.csv", [_pairs_row(0, "multiview")], current)
    tasks = {n: dataclasses.replace(t, tracks=True) for n, t in current.tasks.items()}
    older = dataclasses.replace(current, tasks=tasks)
    data = json.loads(older.to_json())
    for task in data["tasks"].values():
        task.pop("tracks")
    (tmp_path / "vocabulary.json").write_text(json.dumps(data))
    rows = [_pairs_row(s, p) for s in (0, 1) for p in ("multiview", "twoview")]
    append_runs(tmp_path / "runs.csv", [*rows, _pairs_row(0, "twoview", "tri")], older)
    with pytest.raises(BenchError, match="bench upgrade"):
        read_runs(tmp_path / "runs.csv")
    assert main(["upgrade", "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "runs.csv: pairs rows written once per unit, protocol none (2 kept, 2 duplicates" in out
    runs = read_runs(tmp_path / "runs.csv")
    assert sorted(zip(runs["task"], runs["protocol"], runs["seed"])) == [
        ("pairs", "none", 0),
        ("pairs", "none", 1),
        ("tri", "twoview", 0),  # a task with tracks: as it was
    ]
    assert main(["upgrade", "--results", str(tmp_path)]) == 0
    assert "up to date" in capsys.readouterr().out


def test_an_upgrade_never_makes_an_altered_row_valid(tmp_path, capsys):
    """`bench upgrade` rewrites the pairs rows once per unit; a row whose value was edited
    by hand (its checksum no longer holds) stays altered, and is refused as such after."""
    from bench.runs import DamagedRuns, append_runs

    current = Vocabulary.current()
    tasks = {n: dataclasses.replace(t, tracks=True) for n, t in current.tasks.items()}
    data = json.loads(dataclasses.replace(current, tasks=tasks).to_json())
    for task in data["tasks"].values():
        task.pop("tracks")
    (tmp_path / "vocabulary.json").write_text(json.dumps(data))
    older = dataclasses.replace(current, tasks=tasks)
    rows = [_pairs_row(s, p) for s in (0, 1) for p in ("multiview", "twoview")]
    append_runs(tmp_path / "runs.csv", rows, older)
    text = (tmp_path / "runs.csv").read_text().splitlines()
    kept = next(i for i, line in enumerate(text) if ",1,texture,64,pairs,multiview," in line)
    text[kept] = text[kept].replace(",0.5,", ",0.9,")  # auc_10 edited by hand
    (tmp_path / "runs.csv").write_text("\n".join(text) + "\n")
    assert main(["upgrade", "--results", str(tmp_path)]) == 2  # upgraded, the damage refused
    assert "altered" in capsys.readouterr().err
    with pytest.raises(DamagedRuns, match="altered"):
        read_runs(tmp_path / "runs.csv")


def test_a_file_that_cannot_be_written_is_one_line_and_the_rows_are_kept(
    small_run, tmp_path, capsys
):
    """A page that cannot be replaced (here a folder in its place; an immutable file in
    the report) ended in a traceback; now one line naming it, the rows untouched."""
    r = tmp_path / "r"
    shutil.copytree(small_run, r)
    (r / "README.md").unlink()
    (r / "README.md").mkdir()
    (r / "README.md" / "x").write_text("")
    before = (r / "runs.csv").read_bytes()
    assert main(["plot", "--results", str(r)]) == 2
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if x.startswith("bench: error:")]
    assert "README.md" in line and "already written is kept" in line
    assert (r / "runs.csv").read_bytes() == before


def test_no_row_is_deleted_a_stale_one_is_moved_aside_and_said(
    quick_results, renders_dir, tmp_path, capsys, monkeypatch
):
    """After an edit of the code (here: the rows' hashes made another code's), a narrower
    grid computes its own rows again; the stale rows outside it are moved, as they were,
    to runs.stale.csv, said in the log, and read there as runs."""
    from bench.runs import ROW_CHECKSUM, read_runs, row_checksum
    from tests.conftest import bench_run, rows_of

    table_pairs = lambda r: (r["scene"] == "table") & (r["task"] == "pairs")  # noqa: E731
    keep = lambda r: table_pairs(r) & r["method"].isin(["texture", "colmap-b"])  # noqa: E731
    folder = rows_of(quick_results, tmp_path / "keep", keep)
    rows = pd.read_csv(folder / "runs.csv", dtype=str, keep_default_na=False)
    rows["prediction_hash"] = "0ther0c0de000"
    rows[ROW_CHECKSUM] = [row_checksum(r) for r in rows.to_dict("records")]
    rows.to_csv(folder / "runs.csv", index=False)
    grid = dataclasses.replace(
        small_grid_of(("table",), ("texture",)), tasks=("pairs",), protocols=("multiview",)
    )
    bench_run(grid, folder, renders_dir)
    err = capsys.readouterr().err
    assert "2 row(s) of " in err and "moved, as they were, to runs.stale.csv" in err
    stale = read_runs(folder / "runs.stale.csv")
    assert sorted(stale["method"]) == ["colmap-b", "texture"]
    assert set(stale["prediction_hash"]) == {"0ther0c0de000"}
    assert list(read_runs(folder / "runs.csv")["method"]) == ["texture"]


def small_grid_of(scenes, methods):
    from tests.conftest import small_grid

    return dataclasses.replace(small_grid(), scenes=scenes, methods=methods)


def test_a_closed_pipe_ends_a_listing_quietly(tmp_path):
    """`bench scenes | head`: the reader stopped; nothing is wrong, nothing is said."""
    err = tmp_path / "err"
    cmd = f'"{sys.executable}" -m bench scenes 2>"{err}" | head -c 10 >/dev/null'
    subprocess.run(["bash", "-c", cmd], cwd=ROOT, check=True, timeout=120)
    assert err.read_text() == ""


def test_every_help_text_reads_as_it_is_meant():
    """No `%%` (argparse doubles only what it formats), every command."""
    from bench.cli import COMMANDS

    for command in COMMANDS:
        text = build_parser(command).format_help()
        assert "%%" not in text, command
