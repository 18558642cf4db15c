"""The results folder's layout: every file a run and its report write (named here alone),
the `Workspace` (where a run reads and writes) and the lock one bench process at a time
holds on a folder (`holding`: a run, `bench plot` or `bench publish`; another is refused
in one line while it does). Its rows' contract is `bench.runs`, its binding to its
settings `bench.binding`, its upgrades `bench.upgrades`.
"""

from __future__ import annotations

import os
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

from bench.files import exclusive
from bench.vocabulary import (
    HEADLINE,
    NO_PROTOCOL,
    Job,
    Unit,
)

# The results folder's layout: every file a run and its report write, named here alone
# (tests/test_layout.py fails where another module spells one).
RUNS = "runs.csv"
DAMAGED = "runs.damaged.csv"
"""Damaged rows set aside (`set_aside_damaged`)."""
STALE = "runs.stale.csv"
"""Rows a run replaced or no longer counts as current (`keep_runs`): moved here, never
deleted, in `runs.csv`'s own format (checksums kept)."""
ORIGIN = "origin.json"
"""A published snapshot's origin: what made its rows (`bench.harness.origin`)."""
CONFIG = "config.json"
"""The settings the folder is bound to (`bind_results_dir`)."""
VOCABULARY = "vocabulary.json"
"""The methods, tasks and metrics its rows were computed under (`read_vocabulary`)."""
MANIFEST = "manifest.json"
"""Versions, machine, settings and the invocations that computed the rows."""
PAGE = "README.md"
"""The results page (`bench.report.page`)."""
GALLERY = "scenes.png"
"""The contact sheet of the scenes (`bench gallery`)."""
LOCK = ".bench-run.lock"
MODELS = "models"
"""One folder per unit (`Workspace.unit_dir`): its prediction and models."""
PREDICTION = "prediction"
"""A unit's stored prediction: `prediction.json` (written last) and `prediction-<grant>.npz`
(`bench.unit.predict`)."""
LOOP = "loop.json"
"""Beside the model of a multi-view policy: its rounds."""
POINT_ERRORS = "point_errors.csv"
"""Beside a tri model: each point's distance to the ground-truth surface (Figure 2)."""
TABLES = (
    "table1.csv",
    "table1_twoview.csv",
    "table2.csv",
    "paired.csv",
    "paired_sfm.csv",
    "table_scenes.csv",
    "frontend_cost.csv",
    "table3.csv",
)
"""The report's tables (`bench.report.tables`; Table 3, of the nbv task: `bench.report.nbv`)."""
TABLE1, TABLE1_TWOVIEW, TABLE2, PAIRED, PAIRED_SFM, TABLE_SCENES, FRONTEND_COST, TABLE3 = TABLES
# The equal-keypoint comparison (`bench.report.tables.equal_keypoints`), where it ran.
TABLE1_EQUAL = "table1_equal.csv"
# The verdicts per category of `sees` (`bench.report.categories.category_verdicts`).
VERDICTS = "verdicts.csv"
# The cost per method and budget, and quality against it (`bench.report.cost`).
TABLE_COST, FIGURE_COST = "table_cost.csv", "figure_cost"
# Which detector and which selection at a budget, across pools (`bench.report.pools`).
TABLE_POOLS = "table_pools.csv"
FIGURES = ("figure2", "figure3", "figure_budget", "figure_views")
"""The report's figures, without their suffix (`.png`; Figure 3 also `.pdf`)."""
FIGURE2, FIGURE3, FIGURE_BUDGET, FIGURE_VIEWS = FIGURES
TRANSFER, TRANSFER_RANKS, FIGURE_TRANSFER = "transfer.csv", "transfer_ranks.csv", "figure_transfer"
"""A dataset folder's ranking against rendered folders (`bench.report.transfer`)."""


def png(figure: str) -> str:
    return f"{figure}.png"


def table1_of(scene: str) -> str:
    """A dataset folder's Table 1 of one of its datasets."""
    return f"table1-{scene}.csv"


@dataclass(frozen=True)
class Workspace:
    """Where a run reads and writes: its results folder and the render cache."""

    results: Path
    renders: Path

    @property
    def runs_csv(self) -> Path:
        return self.results / RUNS

    def unit_dir(self, unit: Unit) -> Path:
        """A unit's folder: its prediction, and the headline job's model at the top."""
        return (
            self.results / MODELS / f"{unit.scene}-s{unit.seed}" / f"{unit.method}-b{unit.budget}"
        )

    def model_dir(self, unit: Unit, job: Job) -> Path:
        """Where a job's model is exported: the headline task's folder is the unit's, any
        other task's a subfolder named after it; in it, the headline protocol's model at
        the top and any other protocol's in a subfolder named after the protocol (e.g.
        `twoview/`, `sfm/`, `sfm/twoview/`; a task without tracks, `pairs/`, at the top)."""
        folder = self.unit_dir(unit)
        if job.task != HEADLINE[0]:
            folder = folder / job.task
        return folder if job.protocol in (HEADLINE[1], NO_PROTOCOL) else folder / job.protocol


def holding(folder: Path, reading: bool = False):
    """Hold a results folder (or snapshot) for a run, `bench plot` or `bench publish`:
    another bench process is refused in one line while one does. `reading`: a folder that
    cannot be written is read without the lock (no run can write there either)."""
    folder = Path(folder)
    if reading and folder.is_dir() and not os.access(folder, os.W_OK):
        return nullcontext()
    return exclusive(folder / LOCK, f"results folder {folder}")
