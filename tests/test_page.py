"""The results page (`README.md` of a results folder): written from the folder's files alone."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from bench.report.page import PAGE, results_page
from bench.report.tables import with_shares
from bench.report.write import write_tables
from bench.results import read_runs
from bench.vocabulary import Vocabulary

PUBLISHED = Path(__file__).resolve().parents[1] / "results" / "published"


@pytest.mark.parametrize("regime", ["published", "published-dense"])
def test_the_published_page_is_what_its_runs_csv_gives(tmp_path, regime):
    """Every table of each regime's published snapshot computed again from its runs.csv
    alone gives its page, word for word: no number on it is typed by hand or left from
    older rows."""
    snapshot, folder = PUBLISHED.with_name(regime), tmp_path / regime
    shutil.copytree(snapshot, folder, ignore=shutil.ignore_patterns("*.csv", PAGE))
    shutil.copyfile(snapshot / "runs.csv", folder / "runs.csv")
    vocab = Vocabulary.load(folder)
    df = with_shares(read_runs(folder / "runs.csv"), vocab)
    write_tables(df, folder, vocab)
    assert results_page(folder) == (snapshot / PAGE).read_text()


def test_the_page_shows_each_interval_and_no_interval_where_a_table_has_none(tmp_path):
    shutil.copyfile(PUBLISHED / "vocabulary.json", tmp_path / "vocabulary.json")
    runs = pd.read_csv(PUBLISHED / "runs.csv", nrows=3)
    runs.to_csv(tmp_path / "runs.csv", index=False)
    pd.DataFrame(
        {
            "strategy": ["Texture-only", "Random budget"],
            "method": ["texture", "random"],
            "budget": [256, 256],
            "runs": [5, 1],
            "rmse": [0.5, 0.125],
            "rmse_lo": [0.25, None],
            "rmse_hi": [0.75, None],
        }
    ).to_csv(tmp_path / "table1.csv", index=False)
    page = results_page(tmp_path)
    assert "| Texture-only | 256 | 5 | 0.5 [0.25, 0.75] |" in page
    assert "| Random budget | 256 | 1 | 0.125 |" in page  # one run: the mean alone
    assert "figure3.png" not in page  # no figure drawn, none shown
