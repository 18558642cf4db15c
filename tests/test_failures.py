"""A failing method is a value: its rows say what failed and where, the grid and its tables
are finished, and the run ends non-zero with one line; the messages a user reads name the
mistake (a policy's return value, a list with spaces, the figures' panels and notes)."""

from __future__ import annotations

import colorsys
import math

import numpy as np
import pandas as pd
import pytest

from bench.camera import look_at
from bench.cli import main
from bench.cli.common import parse_list
from bench.frontend.features import Candidates
from bench.frontend.policies import POLICIES, PolicyFailed, PolicyInput, policy, select
from bench.frontend.signals import SIGNALS, Signals
from bench.frontend.views import View
from bench.report import figures
from bench.results import read_runs
from bench.summary import exclusions, failures
from bench.vocabulary import METHODS, REFERENCE_MAPS, Vocabulary

LATE = """\
from bench.frontend.policies import policy

CALLS = []


@policy("late-fail")
def late_fail(inp, budget, rng, cfg):
    CALLS.append(inp.view.index)
    if len(CALLS) % 3 == 0:
        raise RuntimeError(f"boom on call {len(CALLS)}")
    return list(range(budget))
"""
RAISE_LINE = LATE.splitlines().index('        raise RuntimeError(f"boom on call {len(CALLS)}")') + 1


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_raising_plugin_fails_its_rows_saying_where_and_the_grid_finishes(
    workers, renders_dir, tmp_path, capsys
):
    module = tmp_path / "late.py"
    module.write_text(LATE)
    argv = ["run", "--scenes", "table", "--seeds", "0", "--budget", "16", "--workers", workers]
    argv += ["--width", "64", "--height", "48", "--spp", "2", "--max-depth", "2"]
    argv += ["--methods", "texture,late-fail", "--tasks", "tri", "--protocols", "multiview"]
    argv += ["--policy-module", str(module), "--results", str(tmp_path / "r")]
    run = lambda: main([*argv, "--renders", str(renders_dir)])  # noqa: E731
    try:
        assert run() == 2
        runs = read_runs(tmp_path / "r" / "runs.csv")
        (late,) = runs[runs["method"] == "late-fail"].itertuples()
        assert late.status == "failed"
        for where in ("RuntimeError: boom on call 3", "view 2 ", f"{module}:{RAISE_LINE}"):
            assert where in late.failure
        assert "in table seed 0, task tri" in late.failure
        assert (runs["method"] == "texture").sum() == 1  # every other row is written
        assert (tmp_path / "r" / "table1.csv").is_file()
        assert (tmp_path / "r" / "figure3.png").is_file()
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith("bench: error: 1 row(s) could not be computed, of late-fail (1)")
        assert f"{module}:{RAISE_LINE}" in err[-1] and "Traceback" not in "\n".join(err)
        summary = [line for line in err if "of the grid's 2 rows, " in line]
        assert summary and "1 tri: error of late-fail" in summary[0]
        assert not any("figure2.png not drawn" in line for line in err)  # nobody asked for it
        assert run() == 2  # computed again, not reused
        again = "1 row(s) could not be computed last time; computing them again"
        assert again in capsys.readouterr().err
    finally:
        POLICIES.pop("late-fail", None), METHODS.pop("late-fail", None)


def _input() -> PolicyInput:
    rng = np.random.default_rng(0)
    n = 20
    cam = look_at((0.0, -5.0, 1.0), (0.0, 0.0, 1.0), width=64, height=48)
    view = View(0, "v.png", np.zeros((48, 64, 3), np.uint8), cam)
    cand = Candidates(
        rng.uniform(0, 48, (n, 2)),
        np.full(n, 3.0),
        np.zeros(n),
        rng.uniform(0, 1, n),
        rng.normal(size=(n, 128)).astype(np.float32),
    )
    return PolicyInput(view, cand, Signals(**{s: rng.uniform(0, 1, n) for s in SIGNALS}))


@pytest.mark.parametrize(
    "returns, message",
    [
        (lambda b: None, "returned None (missing return?)"),
        (lambda b: (np.arange(b), np.ones(b)), "returned a tuple of 2, not one array"),
        (lambda b: {"indices": np.arange(b)}, "returned a dict, not an array"),
        (lambda b: np.arange(b) + 0.5, "broke the contract rule 'integer indices': float64"),
    ],
)
def test_a_policys_wrong_return_value_is_named_with_its_file(returns, message):
    def wrong(inp, budget, rng, cfg):
        return returns(budget)

    policy("wrong")(wrong)
    try:
        with pytest.raises(PolicyFailed) as e:
            select("wrong", _input(), 5, np.random.default_rng(0))
    finally:
        POLICIES.pop("wrong"), METHODS.pop("wrong")
    assert str(e.value).startswith(f"policy wrong {message}")
    assert f"view 0 'v.png', at {__file__}:" in str(e.value)


def test_list_options_ignore_spaces_around_items():
    assert parse_list("--scenes", "table, facade") == ("table", "facade")
    assert parse_list("--seeds", " 0-2 ,5", int) == (0, 1, 2, 5)


def _table1(policies: list[str], metrics: dict[str, list[float]], budget: int = 256):
    t = pd.DataFrame({"method": policies, "strategy": policies, "budget": budget})
    for m, _ in Vocabulary.current().panels():
        values = metrics.get(m, [math.nan] * len(policies))
        t[m], t[f"{m}_lo"], t[f"{m}_hi"] = values, values, values
    return t


def _drawn(monkeypatch) -> dict:
    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.update(fig=fig))
    return drawn


def test_figure3_of_an_sfm_only_run_draws_its_panels_alone_with_n_a_inside(monkeypatch, tmp_path):
    drawn = _drawn(monkeypatch)
    t1 = _table1(["texture", "random", "colmap"], {"sfm_maa": [0.4, 0.3, math.nan]})
    figures.figure3(t1, Vocabulary.current(), tmp_path / "figure3")
    (ax,) = drawn["fig"].axes  # one panel: no empty ones for the task that did not run
    assert "mAA" in ax.get_title()
    (na,) = [t for t in ax.texts if t.get_text() == "n/a"]
    lo, hi = ax.get_xlim()
    assert lo < na.get_position()[0] - 0.4 and na.get_position()[0] + 0.4 < hi
    figures.figure3(
        t1, Vocabulary.current(), tmp_path / "figure3", note="3 failed (2 sfm: the mapper ...)"
    )
    assert "3 failed (2 sfm: the mapper ...)" in [t.get_text() for t in drawn["fig"].texts]


def test_the_budget_figures_lines_never_share_a_hue_and_a_style(monkeypatch, tmp_path):
    drawn = _drawn(monkeypatch)
    names = [f"p{k}" for k in range(12)]
    t1 = pd.concat(
        [_table1(names, {"acc_completeness_pct": list(range(12))}, budget=b) for b in (128, 256)]
    )
    figures.figure_budget(t1, Vocabulary.current(), tmp_path / "figure_budget")
    lines = drawn["fig"].axes[0].get_lines()
    assert len(lines) == 12
    seen = {}
    for line in lines:
        hue = colorsys.rgb_to_hsv(*matplotlib_rgb(line.get_color()))[0]
        style = (line.get_marker(), str(line.get_linestyle()))
        for other in seen.get(style, []):
            assert min(abs(hue - other), 1 - abs(hue - other)) > 0.02
        seen.setdefault(style, []).append(hue)


def matplotlib_rgb(color) -> tuple[float, float, float]:
    from matplotlib.colors import to_rgb

    return to_rgb(color)


def test_the_summary_says_what_failed_by_reason_and_which_cells_sfm_leaves_out():
    rows = pd.DataFrame(
        {
            "scene": ["table", "table", "facade", "facade", "corridor"],
            "seed": [0, 0, 0, 0, 1],
            "method": ["texture", "texture", "texture", "colmap", "texture"],
            "task": ["sfm", "tri", "sfm", "sfm", "sfm"],
            "status": ["failed", "failed", "failed", "ok", "ok"],
            "failure": [
                "the mapper registered 0 view(s)",
                "no pair of views has verified matches",
                "the mapper registered 1 view(s)",
                "",
                "",
            ],
            REFERENCE_MAPS: [0, 0, 1, 1, 0],
        }
    )
    assert failures(rows) == (
        "3 failed (2 sfm: the mapper registered N view(s); "
        "1 tri: no pair of views has verified matches)"
    )
    assert exclusions(rows, Vocabulary.current()) == (
        "sfm means leave out 2 of 3 (scene, seed): corridor seed 1, table seed 0 "
        "(colmap with all features does not map them)"
    )
