"""Reproduction by anyone: `bench reproduce` recomputes a slice of a snapshot under its own
settings and compares every metric column with it; `bench verdict` computes a policy
module's rows alone beside a snapshot's and states its verdict against its peer."""

from __future__ import annotations

import shutil

import pandas as pd
import pytest

from bench import ROOT
from bench.cli import main
from bench.runs import ROW_CHECKSUM, row_checksum
from tests.conftest import POLICIES, spy


def test_reproduce_says_identical_then_names_what_moved(
    quick_results, renders_dir, tmp_path, capsys
):
    published, here = tmp_path / "published", tmp_path / "here"
    shutil.copytree(quick_results, published)
    argv = ["reproduce", "--published", str(published), "--scenes", "table", "--budget", "64"]
    argv += ["--results", str(here), "--renders", str(renders_dir), "--workers", "1"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "identical: every metric value of every common row" in out
    assert "--methods " + ",".join(sorted(POLICIES)) in out
    rows = pd.read_csv(published / "runs.csv", dtype=str, keep_default_na=False)
    held = pd.to_numeric(rows["coverage_pct"], errors="coerce") > 0
    k = rows.index[(rows["scene"] == "table") & (rows["method"] == "texture") & held][0]
    rows.loc[k, "coverage_pct"] = str(float(rows.loc[k, "coverage_pct"]) / 2)
    rows[ROW_CHECKSUM] = [row_checksum(r) for r in rows.to_dict("records")]
    rows.to_csv(published / "runs.csv", index=False)
    with pytest.raises(SystemExit) as stop:
        main(argv)  # nothing computed again: the slice's rows are there
    assert stop.value.code == 1
    out = capsys.readouterr().out
    assert "1 value(s) moved in 1 column(s):" in out and "coverage_pct: 1 value(s)" in out


def test_reproduce_refuses_what_it_cannot_compare(quick_results, tmp_path, capsys):
    published = tmp_path / "published"
    shutil.copytree(quick_results, published)
    argv = ["reproduce", "--published", str(published), "--scenes", "corridor"]
    assert main(argv + ["--results", str(tmp_path / "x")]) == 2
    assert "holds no rows of scenes corridor, seeds 0 at budget 256" in capsys.readouterr().err


def test_verdict_computes_the_modules_rows_alone_beside_the_snapshot(
    quick_results, renders_dir, tmp_path, capsys, monkeypatch
):
    from bench.cli import verdict

    root = tmp_path / "root"
    shutil.copytree(quick_results, root / "results" / "published")
    monkeypatch.setattr(verdict, "ROOT", root)
    calls = []
    spy(monkeypatch, calls)
    module = ROOT / "examples" / "my_policy.py"
    out = tmp_path / "v"
    argv = ["verdict", str(module), "--regimes", "sparse", "--results", str(out), "--workers", "1"]
    assert main(argv + ["--renders", str(renders_dir)]) == 0
    assert calls == [("center-texture", 64)] * 2  # its two cells, nothing else
    rows = pd.read_csv(out / "sparse" / "runs.csv")
    published = pd.read_csv(quick_results / "runs.csv")
    assert len(rows) == len(published) + 2 * 5 and rows["pixels"].nunique() == 2  # 2 scenes
    said = capsys.readouterr().out
    assert "`center-texture`" in said and "against the best own-image peer" in said
    assert main(["verdict", str(tmp_path / "none.py")]) == 2
    assert "none.py is not a file" in capsys.readouterr().err
