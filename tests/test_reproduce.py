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
from tests.conftest import POLICIES, snapshot_of, spy


def test_reproduce_says_identical_then_names_what_moved(
    quick_results, renders_dir, tmp_path, capsys
):
    published = snapshot_of(quick_results, tmp_path / "published")
    here = tmp_path / "here"
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
    assert "moved: 1 value(s) in 1 column(s):" in out and "coverage_pct: 1 value(s)" in out
    rows = pd.read_csv(published / "runs.csv", dtype=str, keep_default_na=False)
    rows["pixels"] = "px-0ther0pixels"  # a snapshot of other renders, every value the same
    rows[ROW_CHECKSUM] = [row_checksum(r) for r in rows.to_dict("records")]
    rows.to_csv(published / "runs.csv", index=False)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 1
    assert "the rows read other pixels: px-0ther0pixels and px-" in capsys.readouterr().out


def test_reproduce_refuses_what_it_cannot_compare(quick_results, tmp_path, capsys):
    published = tmp_path / "published"
    shutil.copytree(quick_results, published)
    argv = ["reproduce", "--published", str(published), "--results", str(tmp_path / "x")]
    assert main([*argv, "--scenes", "corridor", "--budget", "64"]) == 2
    assert "holds no rows of scenes corridor, seeds 0 at budget 64" in capsys.readouterr().err
    for budget in ("300", "0"):  # before any work: no folder is made
        assert main([*argv, "--budget", budget]) == 2
        err = capsys.readouterr().err
        assert f"--budget {budget}: " in err and "holds budgets 64" in err
    assert not (tmp_path / "x").exists()


def _frontier_snapshot(quick_results, renders_dir, root):
    """The session's small grid published as a regime's snapshot is: with the frontier
    peer `colmap-b` at a budget of its own (96), its origin recorded."""
    import dataclasses

    from tests.conftest import bench_run, small_grid

    grown = root / "grown"
    shutil.copytree(quick_results, grown)
    grid = dataclasses.replace(small_grid(), methods=("colmap-b",), frontier=(96,))
    bench_run(grid, grown, renders_dir)
    return snapshot_of(grown, root / "results" / "published")


def test_verdict_computes_the_modules_rows_alone_beside_the_snapshot(
    quick_results, renders_dir, tmp_path, capsys, monkeypatch
):
    import json

    from bench.cli import verdict

    root = tmp_path / "root"
    published = _frontier_snapshot(quick_results, renders_dir, root)
    before = {p.name: p.read_bytes() for p in published.iterdir() if p.is_file()}
    monkeypatch.setattr(verdict, "ROOT", root)
    calls = []
    spy(monkeypatch, calls)
    module = ROOT / "examples" / "my_policy.py"
    out = tmp_path / "v"
    argv = ["verdict", str(module), "--regimes", "sparse", "--results", str(out), "--workers", "1"]
    argv += ["--renders", str(renders_dir)]
    assert main(argv) == 0
    assert calls == [("center-texture", 64)] * 2  # its two cells at the grid's budget alone
    rows = pd.read_csv(out / "sparse" / "runs.csv")
    assert set(rows["method"]) == {"center-texture"} and len(rows) == 2 * 5
    said = capsys.readouterr().out
    assert "commit test, 78 rows" in said and "the code is the snapshot's" in said
    assert said.count("`center-texture` (") == 2  # sfm and pairs at 64: never at 96
    assert "against the best own-image peer, `colmap-b`" in said and "B = 96" not in said
    # the code differs from the snapshot's (as after an edit of a module in the key): the
    # module is named, a cell of the peers computed again and compared, nothing published
    # recomputed, copied or changed, and the verdict still printed
    origin = json.loads((published / "origin.json").read_text())
    origin["modules"]["bench.harness.execute"] = "edited"
    (published / "origin.json").write_text(json.dumps(origin))
    before["origin.json"] = (published / "origin.json").read_bytes()
    calls.clear()
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "differs from the snapshot's in 1 module(s): bench.harness.execute" in said
    assert "its peers' cell facade seed 0 at 64 computed again:" in said
    assert "identical: every metric value of every common row" in said
    assert said.count("`center-texture` (") == 2
    assert set(calls) == {("colmap-b", 64), ("colmap", 0)}  # the peers' cell, no policy row
    assert before == {p.name: p.read_bytes() for p in published.iterdir() if p.is_file()}
    assert main(["verdict", str(tmp_path / "none.py")]) == 2
    assert "none.py is not a file" in capsys.readouterr().err


def test_verdict_refuses_bad_input_before_any_work(tmp_path, capsys):
    garbage = tmp_path / "garbage.py"
    garbage.write_bytes(b"\xff\xfe\x00policy")
    module = str(ROOT / "examples" / "my_policy.py")
    cases = {
        (str(garbage),): "garbage.py is not UTF-8 text",
        (module, "--workers", "0"): "--workers must be at least 1, got 0",
        (module, "--workers", "-1"): "--workers must be at least 1, got -1",
        (module, "--dataset", str(tmp_path / "nonexistent")): "nonexistent",
        (module, "--regimes", "sparse,wide"): "unknown regime 'wide'",
    }
    for args, line in cases.items():
        out = tmp_path / "v"
        assert main(["verdict", *args, "--results", str(out)]) == 2
        err = capsys.readouterr().err
        assert line in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()


def test_verdict_without_any_verdict_says_why_and_fails(
    quick_results, renders_dir, tmp_path, capsys, monkeypatch
):
    """A snapshot without the peers of the module's category: every line says why, and a
    run that judged nothing exits 1."""
    from bench.cli import verdict
    from tests.conftest import rows_of

    root = tmp_path / "root"
    peerless = rows_of(quick_results, tmp_path / "p", lambda r: r["method"] != "colmap-b")
    snapshot_of(peerless, root / "results" / "published")
    monkeypatch.setattr(verdict, "ROOT", root)
    module = str(ROOT / "examples" / "my_policy.py")
    argv = ["verdict", module, "--regimes", "sparse", "--results", str(tmp_path / "v")]
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--workers", "1", "--renders", str(renders_dir)])
    assert stop.value.code == 1
    said = capsys.readouterr().out
    assert said.count("`center-texture` at B = 64 in `") == 2  # sfm and pairs, each with why
    assert said.count("judged by no verdict: no peer of the category ran; add `colmap-b`") == 2


def _rows(**metrics) -> pd.DataFrame:
    """Two hand-made rows of a snapshot, keyed as `runs.csv`'s, with `metrics`' values."""
    key = {"scene": ["facade"] * 2, "seed": [0, 0], "method": ["colmap-b"] * 2}
    key |= {"budget": [256, 256], "bag": ["", ""], "task": ["sfm", "tri"]}
    key |= {"protocol": ["multiview"] * 2, "pixels": ["px-a"] * 2}
    return pd.DataFrame(key | {k: list(v) for k, v in metrics.items()})


def test_reproduce_classes_last_bits_of_a_residual_apart_from_a_moved_score():
    """Bundle adjustment's residuals may move in their last bits between CPU families
    (equal but for last bits); a score moved by one ulp has moved."""
    import numpy as np

    from bench.report.compare import compare_rows

    published = _rows(maa=[0.5, np.nan], rmse=[0.123456789, 0.2], points=[100, 200])
    same = compare_rows(published, published.copy())
    assert not same.moved and not same.last_bits
    assert same.lines()[-1] == "identical: every metric value of every common row"
    bits = published.copy()
    bits.loc[0, "rmse"] = 0.123456789 + 1.06e-9  # as measured on an AMD EPYC
    close = compare_rows(published, bits)
    assert not close.moved and close.last_bits["rmse"][0] == 1
    said = "\n".join(close.lines())
    assert "equal but for floating-point last bits: 1 value(s) of rmse" in said
    assert "('facade', 0, 'colmap-b', 256, '', 'sfm', 'multiview'): 0.123456789 -> 0.12345" in said
    assert "np." not in said  # plain keys and values
    ulp = published.copy()
    ulp.loc[0, "maa"] = np.nextafter(0.5, 1.0)
    moved = compare_rows(published, ulp)
    assert list(moved.moved) == ["maa"] and not moved.last_bits
    far = published.copy()
    far.loc[1, "rmse"] = 0.2001  # a residual beyond the tolerance has moved
    assert list(compare_rows(published, far).moved) == ["rmse"]


def test_a_pool_modules_verdict_runs_its_pool_alone_beside_the_cross_pool_snapshot(
    quick_results, renders_dir, tmp_path, capsys, monkeypatch
):
    """`bench verdict` on a pool module (examples/my_pool.py): its pool's own top-B and the
    snapshot's selections named by --methods, on its pool alone, judged against the
    cross-pool snapshot's `colmap-b`; nothing of the snapshot is computed again."""
    from bench.cli import verdict

    root = tmp_path / "root"
    snapshot_of(quick_results, root / "results" / "published-pools")
    monkeypatch.setattr(verdict, "ROOT", root)
    calls = []
    spy(monkeypatch, calls)
    out = tmp_path / "v"
    argv = ["verdict", str(ROOT / "examples" / "my_pool.py"), "--results", str(out)]
    argv += ["--workers", "1", "--renders", str(renders_dir)]
    assert main([*argv, "--methods", "oracle"]) == 2  # not a selection: one line
    assert "--methods may name only those" in capsys.readouterr().err
    assert main([*argv, "--methods", "texture"]) == 0
    assert sorted(set(calls)) == [("response:sift-upright", 64), ("texture:sift-upright", 64)]
    rows = pd.read_csv(out / "pools" / "runs.csv")
    assert set(rows["pool"]) == {"sift-upright"} and set(rows["matcher"]) == {"ratio"}
    said = capsys.readouterr().out
    assert "--pools sift-upright" in said
    assert said.count("`texture:sift-upright` (") == 2  # sfm and pairs at 64
    assert "against the best own-image peer, `colmap-b`" in said
