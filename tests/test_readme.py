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
    row |= dict(metric="sfm_maa", kendall_tau=0.5, tau_lo=0.1, tau_hi=0.8, tau_photos=0.3)
    row |= dict(rel_rendered=0.9, rel_dataset=0.8, ceiling=math.sqrt(0.72), tau_note="")
    pd.DataFrame([row]).to_csv(tmp_path / "transfer.csv", index=False)
    sparse = ROOT / "results" / "published"
    said = results_section({"sparse": sparse}, tmp_path)
    assert "- middlebury-temple-sparse, sfm_maa, B = 256, against the 6-view renders: tau" in said
    assert "No snapshot of the photo sets" in results_section({"sparse": sparse}, None)
    for name in ("table1.csv", "paired_sfm.csv", "vocabulary.json"):  # a photo run's tables
        (tmp_path / name).write_bytes((sparse / name).read_bytes())
    said = results_section({"sparse": sparse}, tmp_path)
    assert "| photographs | sfm (sfm_maa) | image | `peak-scale` " in said


def test_the_section_is_replaced_between_its_markers_alone():
    readme = f"# t\n\nbefore\n{BEGIN}\nold\n{END}\nafter\n"
    assert with_section(readme, "new\n") == f"# t\n\nbefore\n{BEGIN}\nnew\n{END}\nafter\n"
    with pytest.raises(BenchError, match="lacks its results markers"):
        with_section("# t\n", "new\n")
