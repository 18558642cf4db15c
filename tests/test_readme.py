"""The repository README's results section: written from the published snapshots
(`bench publish --readme`, `bench.report.summary`), never typed by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from bench import ROOT, BenchError
from bench.cli.publish import readme_section
from bench.report.summary import BEGIN, END, results_section, section_of, with_section


def test_the_readmes_results_section_is_what_the_published_snapshots_give(monkeypatch):
    """It said `cross-view` led the pose-free policies (0.62) where the sparse table had
    `track-first` at 0.98; now `bench publish --readme` writes it, and this fails until it
    is rewritten after a snapshot changes."""
    monkeypatch.chdir(ROOT)
    written = section_of((ROOT / "README.md").read_text())
    assert written == readme_section(), "run `bench publish --readme` in the repository root"
    assert "| sparse | sfm (sfm_maa) | views | `track-first` " in written


def test_the_photographs_verdicts_come_from_a_published_photo_folder(tmp_path):
    row = dict(dataset="middlebury-temple-sparse", rendered_views=6, matched=True, budget=256)
    row |= dict(sees="image")
    row |= dict(metric="sfm_maa", kendall_tau=0.5, tau_lo=0.1, tau_hi=0.8, tau_photos=0.3)
    row |= dict(rel_rendered=0.9, rel_dataset=0.8, ceiling=math.sqrt(0.72), tau_note="")
    pd.DataFrame([row]).to_csv(tmp_path / "transfer.csv", index=False)
    sparse = ROOT / "results" / "published"
    said = results_section({"sparse": sparse}, tmp_path)
    row = "| middlebury-temple-sparse | sfm (sfm_maa) | image | 0.50 [0.10, 0.80] | 0.90 / 0.80 |"
    assert row + " 0.85 | 0.30 | as well as the others |" in said
    assert "No snapshot of the photo sets" in results_section({"sparse": sparse}, None)
    for name in ("table1.csv", "verdicts.csv", "vocabulary.json"):  # a photo run's tables
        (tmp_path / name).write_bytes((sparse / name).read_bytes())
    said = results_section({"sparse": sparse}, tmp_path)
    assert "| photographs | sfm (sfm_maa) | image | `peak-scale` " in said


def test_the_section_is_replaced_between_its_markers_alone():
    readme = f"# t\n\nbefore\n{BEGIN}\nold\n{END}\nafter\n"
    assert with_section(readme, "new\n") == f"# t\n\nbefore\n{BEGIN}\nnew\n{END}\nafter\n"
    with pytest.raises(BenchError, match="lacks its results markers"):
        with_section("# t\n", "new\n")


def test_the_next_views_gains_come_from_the_published_next_views_table(tmp_path):
    """The README's next-views paragraph carried numbers typed by hand; they are written
    from the snapshot's Table 3 now: the chooser minus each baseline, per score and k."""
    sparse = ROOT / "results" / "published"
    row = dict(scene="all scenes", budget=256, method="weak-triangulation", n=20, wins=12)
    row |= dict(ties=3, losses=5, diff_lo=0.01, diff_hi=0.12)
    table3 = pd.DataFrame(
        [
            row | dict(score="maa", k=1, baseline="random-view", diff=0.064),
            row | dict(score="maa", k=1, baseline="farthest-view", diff=-0.02),
            row | dict(scene="table", score="maa", k=1, baseline="random-view", diff=0.9),
            row | dict(method="random-view", score="maa", k=1, baseline="gap-view", diff=0.9),
        ]
    )
    table3.to_csv(tmp_path / "table3.csv", index=False)
    said = results_section({"sparse": sparse}, None, tmp_path)
    assert "| score | k | - `farthest-view` | - `random-view` |" in said
    assert "| maa | 1 | -0.020 [+0.010, +0.120] 12/3/5 | +0.064 [+0.010, +0.120] 12/3/5 |" in said
    assert "paired over the 20 rendered paths at 256" in said
    assert "Next views" not in results_section({"sparse": sparse}, None, tmp_path / "none")


def test_the_readme_is_read_whole():
    """A newcomer reads it from top to bottom: at most 300 lines (docs/ holds the rest)."""
    assert len((ROOT / "README.md").read_text().splitlines()) <= 300


def test_the_cross_pool_leaders_come_from_the_published_pools_table(tmp_path):
    """Each category's leader across pools at each budget, minus `colmap-b` and minus its
    own pool's top-B, as `table_pools.csv` gives them (a peer is its own top-B)."""
    sparse = ROOT / "results" / "published"
    (tmp_path / "vocabulary.json").write_bytes((sparse / "vocabulary.json").read_bytes())
    at = dict(budget=256, metric="sfm_maa", runs=20, n=20, wins=1, ties=0, losses=0)
    aliked = dict(pool="aliked/lightglue", verdict="above")
    rows = [
        at
        | aliked
        | dict(role="peer", sees="image", method="aliked-b", mean=0.9)
        | dict(vs="colmap-b", mean_diff=0.4, lo=0.2, hi=0.6),
        at
        | aliked
        | dict(role="selection", sees="image", method="quadtree:aliked", mean=0.8)
        | dict(vs="colmap-b", mean_diff=0.3, lo=0.1, hi=0.5),
        at
        | aliked
        | dict(role="selection", sees="views", method="track-first:aliked")
        | dict(mean=0.95, vs="aliked-b", mean_diff=0.05, lo=-0.01, hi=0.11, verdict="tied"),
        at
        | aliked
        | dict(role="selection", sees="views", method="track-first:aliked")
        | dict(mean=0.95, vs="colmap-b", mean_diff=0.45, lo=0.3, hi=0.6),
        at | dict(pool="colmap", role="peer", sees="image", method="colmap-b", mean=0.5, vs=""),
    ]
    pd.DataFrame(rows).to_csv(tmp_path / "table_pools.csv", index=False)
    said = results_section({"sparse": sparse}, None, None, {"renders": tmp_path})
    row = "| renders | 256 | sfm (sfm_maa) | `aliked-b` 0.900 (aliked/lightglue) | +0.400 "
    row += "[+0.200, +0.600] above | itself | `track-first:aliked` 0.950 (aliked/lightglue) | "
    assert row + "+0.450 [+0.300, +0.600] above | +0.050 [-0.010, +0.110] tied |" in said
    assert "`quadtree:aliked`" not in said  # not its category's leader
    both = results_section(
        {"sparse": sparse}, None, None, {"renders": tmp_path, "photos": tmp_path}
    )
    assert "renders and photographs: in sfm at 256 they agree on `aliked-b`." in both
    missing = {"renders": tmp_path / "none"}
    assert "Which detector" not in results_section({"sparse": sparse}, None, None, missing)
