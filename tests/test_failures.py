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
from bench.failures import exclusions, failures, outcomes
from bench.frontend.features import Candidates
from bench.frontend.policies import POLICIES, PolicyFailed, PolicyInput, policy, select
from bench.frontend.signals import SIGNALS, Signals
from bench.frontend.views import View
from bench.report import figures
from bench.runs import read_runs
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
    argv = ["run", "--scenes", "table", "--seeds", "0", "--budget", "16"]
    argv += ["--width", "64", "--height", "48", "--spp", "2", "--max-depth", "2"]
    argv += ["--methods", "texture,late-fail", "--tasks", "tri", "--protocols", "multiview"]
    argv += ["--policy-module", str(module), "--results", str(tmp_path / "r")]

    def run(w=workers):
        return main([*argv, "--workers", w, "--renders", str(renders_dir)])

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
        assert any(line.startswith("bench: runs: 2/2 rows (100 %), ") for line in err)
        summary = [line for line in err if "of the grid's 2 rows, " in line]
        assert summary and "1 tri: error of late-fail" in summary[0]
        assert not any("figure2.png not drawn" in line for line in err)  # nobody asked for it
        # computed again, not reused: decided before any executor starts, so in one process
        assert run("1") == 2
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
    t["runs"], t["note"] = 20, ""
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
    hi, lo = ax.get_ylim()  # the first row on top
    assert lo < na.get_position()[1] - 0.4 and na.get_position()[1] + 0.4 < hi
    figures.figure3(
        t1, Vocabulary.current(), tmp_path / "figure3", note="3 failed (2 sfm: the mapper ...)"
    )
    assert "3 failed (2 sfm: the mapper ...)" in [t.get_text() for t in drawn["fig"].texts]


@pytest.mark.parametrize("panels", [1, 3, 13])
def test_figure3s_title_is_above_every_panel_title(monkeypatch, tmp_path, panels):
    """The overall title overlapped the top row's panel titles (13 panels, a tall figure)."""
    drawn = _drawn(monkeypatch)
    vocab = Vocabulary.current()
    cols = [m for m, _ in vocab.panels()][-panels:]
    t1 = _table1(["texture", "random", "colmap"], {c: [0.4, 0.3, 0.5] for c in cols})
    figures.figure3(t1, Vocabulary.current(), tmp_path / "figure3", note="1 failed (1 sfm: x)")
    fig = drawn["fig"]
    renderer = fig.canvas.get_renderer()
    title = fig._suptitle.get_window_extent(renderer)
    tops = [ax.title.get_window_extent(renderer).y1 for ax in fig.axes]
    assert title.y0 > max(tops) and title.y1 <= fig.bbox.y1


def test_figure3_draws_each_tasks_headline_once_with_a_mark_per_method(monkeypatch, tmp_path):
    """Figure 3 had 13 panels of bars told apart by shades of one hue: now a panel per task
    (its first headline metric), a marker of its own per method within its category."""
    drawn = _drawn(monkeypatch)
    vocab = Vocabulary.current()
    methods = ["random", "texture", "grid", "adaptive", "cross-view", "oracle"]
    t1 = _table1(methods, {m: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6] for m, _ in vocab.panels()})
    figures.figure3(t1, vocab, tmp_path / "figure3")
    axes = drawn["fig"].axes
    titles = dict(vocab.panels())
    assert [ax.get_title() for ax in axes] == [titles[m] for m in vocab.first_headline()]
    ticks = [t.get_text() for t in axes[0].get_yticklabels()]
    assert sorted(ticks) == sorted(methods)
    for sees in ("image", "views"):  # the category named in every panel
        assert all(figures.CATEGORY_NAMES[sees] in [t.get_text() for t in ax.texts] for ax in axes)
    row = dict(zip(axes[0].get_yticks(), ticks))
    points = [c.lines[0] for c in axes[0].containers]  # each method's errorbar
    marker = {row[p.get_ydata()[0]]: p.get_marker() for p in points}
    image = [marker[m] for m in ("random", "texture", "grid")]
    views = [marker[m] for m in ("adaptive", "cross-view")]
    assert len(set(image)) == 3 and len(set(views)) == 2


@pytest.mark.parametrize(
    "runs, excluded, interval, said",
    [
        (4, 0, False, "mean of 4 runs per method, no interval: a scene with 1 seed"),
        (20, 2, True, "mean and 95% interval over 18-20 runs per method"),
        (1, 0, False, "mean of 1 run per method, no interval: a scene with 1 seed"),
    ],
)
def test_figure3s_title_counts_the_runs_as_table1_does(
    monkeypatch, tmp_path, runs, excluded, interval, said
):
    """A quick run (4 scenes, one seed: Table 1's `runs` 4, no interval) was titled "mean
    of one run: no interval"; the runs an sfm mean leaves out are not counted."""
    drawn = _drawn(monkeypatch)
    t1 = _table1(["texture", "random"], {"acc_completeness_pct": [3.0, 1.0], "sfm_maa": [0.5, 0.2]})
    t1["runs"], t1["sfm_excluded_runs"] = runs, excluded
    if not interval:
        for m in ("acc_completeness_pct", "sfm_maa"):
            t1[f"{m}_lo"] = t1[f"{m}_hi"] = math.nan
        t1["note"] = "n/a (1 seed): acc_completeness_pct, sfm_maa"
    figures.figure3(t1, Vocabulary.current(), tmp_path / "figure3")
    title = drawn["fig"]._suptitle.get_text()
    assert said in title and "one run" not in title


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
    assert failures(rows) == (  # each number as its rows had it, never a literal N
        "3 failed (2 sfm: the mapper registered 0 or 1 view(s); "
        "1 tri: no pair of views has verified matches)"
    )
    assert "not an error" in outcomes(rows) and "--quick" in outcomes(rows)
    three = rows.assign(
        failure=[f"the mapper registered {n} view(s) of {n + 5}" for n in (0, 2, 3, 0, 0)]
    )
    assert failures(three).startswith(
        "3 failed (2 sfm: the mapper registered 0 or 3 view(s) of 5 or 8; "
    )
    three = three.assign(task="sfm")
    assert failures(three) == "3 failed (3 sfm: the mapper registered 0 to 3 view(s) of 5 to 8)"
    errors_only = rows.assign(failure="error: RuntimeError: boom (p.py:3)")
    assert "N" not in failures(errors_only) and outcomes(errors_only) == ""
    assert exclusions(rows, Vocabulary.current()) == (
        "sfm means leave out 2 of 3 (scene, seed): corridor seed 1, table seed 0 "
        "(colmap with all features does not map them)"
    )


BOOM = """\
from bench.frontend.policies import policy

CALLS = []


@policy("crash-late", role="baseline")
def crash_late(inp, budget, rng, cfg):
    CALLS.append(inp.view.index)
    if len(CALLS) > 12:  # its first unit (six views under each geometry), then it raises
        raise RuntimeError("crashed")
    return list(range(budget))
"""


def test_a_method_that_crashes_never_ranks_on_the_runs_it_finished(renders_dir, tmp_path):
    """A policy that raises after its first unit: its failed runs enter its means at the
    failure value (AUC 0), a metric without one (rmse) has no mean (incomplete, never the
    best baseline), and Table 1 counts the runs that could not be computed."""
    module = tmp_path / "crash.py"
    module.write_text(BOOM)
    argv = ["run", "--scenes", "table,facade", "--seeds", "0", "--budget", "128", "--workers", "1"]
    # the small grid's renders (conftest.MEDIUM), which the session has
    argv += ["--width", "320", "--height", "240", "--spp", "16", "--max-depth", "2"]
    argv += ["--methods", "texture,crash-late", "--tasks", "tri,pairs", "--protocols", "multiview"]
    argv += ["--policy-module", str(module), "--results", str(tmp_path / "r")]
    try:
        assert main([*argv, "--renders", str(renders_dir)]) == 2
    finally:
        POLICIES.pop("crash-late", None), METHODS.pop("crash-late", None)
    runs = read_runs(tmp_path / "r" / "runs.csv")
    crash = runs[(runs["method"] == "crash-late") & (runs["task"] == "pairs")].set_index("scene")
    assert crash.loc["facade", "failure"].startswith("error: ")  # the second scene's unit
    t1 = pd.read_csv(tmp_path / "r" / "table1.csv").set_index("method")
    assert t1.loc["crash-late", "pairs_auc_10"] == pytest.approx(
        crash.loc["table", "auc_10"] / 2, 1e-5
    )
    assert (t1.loc["crash-late", "error_runs"], t1.loc["crash-late", "pairs_error_runs"]) == (1, 1)
    assert (
        np.isnan(t1.loc["crash-late", "rmse"])
        and "incomplete: 1 of 2 runs" in t1.loc["crash-late", "note"]
    )
    assert t1.loc["texture", "error_runs"] == 0 and not np.isnan(t1.loc["texture", "rmse"])
    t2 = pd.read_csv(tmp_path / "r" / "table2.csv").set_index("scene")
    assert t2.loc["all scenes", "best_baseline_rmse_policy"] == "texture"
    assert np.isnan(t1.loc["crash-late", "pairs_auc_10_tier"])  # a method that raised: no tier
    verdicts = tmp_path / "r" / "verdicts.csv"
    assert not verdicts.exists() or "crash-late" not in verdicts.read_text()


def test_progress_in_a_log_is_a_line_every_few_percent(capsys):
    from bench.console import LOG_STEP_PCT, LogProgress

    with LogProgress("runs", 40, "rows") as bar:
        for _ in range(40):
            bar.update()
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 100 // LOG_STEP_PCT  # 2/40 is 5 %, ..., 40/40 is 100 %
    assert lines[0].startswith("bench: runs: 2/40 rows (5 %), ") and lines[0].endswith(" left")
    assert lines[-1].startswith("bench: runs: 40/40 rows (100 %), ")


def test_progress_counts_its_rate_from_a_reset_and_shows_nothing_where_not_shown(
    capsys, monkeypatch
):
    """A dataset run's first estimate was `41:50 left`: the runs' clock started before the
    long front end; now it restarts when the first front end is ready."""
    from bench import console

    now = [0.0]
    monkeypatch.setattr(console.time, "perf_counter", lambda: now[0])
    with console.LogProgress("runs", 10, "rows") as bar:
        now[0] = 100.0  # the front end took 100 s; no row yet
        bar.reset(total=10)
        now[0] = 101.0
        bar.update()  # one row in 1 s after the reset: 9 left at 1 row/s
    assert capsys.readouterr().err.strip().endswith("1.00 rows/s, 00:09 left")
    with console.progress("render", 1, "scene", shown=False) as bar:
        bar.update()
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("name", sorted(POLICIES))
def test_every_policy_selects_nothing_from_an_empty_pool(name):
    """A view without a candidate (a tiny or flat image): an empty selection, no crash
    (quadtree raised IndexError)."""
    from dataclasses import replace

    inp = _input()
    c = inp.candidates
    empty = Candidates(c.xy[:0], c.size[:0], c.angle[:0], c.response[:0], c.descriptors[:0])
    inp = replace(inp, candidates=empty, signals=Signals(**{s: np.zeros(0) for s in SIGNALS}))
    budget = 0 if METHODS[name].whole_pool else 8
    assert select(name, inp, budget, np.random.default_rng(0)).size == 0


def test_the_failure_note_names_renders_only_where_rows_were_rendered():
    """A photo run without --quick was told failures were expected "at small budgets and
    renders (--quick)"."""
    rows = pd.DataFrame({"status": ["failed", "ok"], "failure": ["no map", ""]})
    assert outcomes(rows).endswith("at small budgets and renders (--quick)")
    assert outcomes(rows.assign(bag=["a.png b.png", "a.png b.png"])).endswith("at small budgets")
