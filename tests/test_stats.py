"""The tables' statistics: intervals that do not overstate, and the sfm exclusion rule
applied the same way whatever the grid holds."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats as scipy_stats

from bench import BenchError
from bench.binding import read_vocabulary
from bench.cli import main
from bench.evaluation.export import export_dataset
from bench.harness.grid import with_reference
from bench.report.stats import paired_difference, stratified_interval
from bench.report.tables import headline_frame, paired, paired_sfm, table1, with_shares
from bench.results import VOCABULARY
from bench.runs import ROW_CHECKSUM, append_runs, mark_reference, read_runs
from bench.unit.config import RunConfig
from bench.vocabulary import REFERENCE_MAPS, Vocabulary
from tests.conftest import MEDIUM, rows_of

# --- intervals ---------------------------------------------------------------------


def _tri_rows(seeds, scenes=("a", "b", "c", "d")) -> pd.DataFrame:
    """Headline rows of adaptive and texture, adaptive ahead by 2 to 3.5 points."""
    rows = []
    for i, scene in enumerate(scenes):
        for seed in seeds:
            cell = dict(scene=scene, seed=seed, budget=64, task="tri", protocol="multiview")
            ahead = 2.5 + 0.5 * (seed % 2) + 0.5 * i
            for policy, value in (
                ("texture", 40.0 + i + seed),
                ("adaptive", 40 + i + seed + ahead),
            ):
                rows.append(cell | dict(method=policy, acc_completeness_pct=value, status="ok"))
    return pd.DataFrame(rows)


def test_a_one_seed_table_shows_no_interval_and_says_why():
    """One seed per scene: resampling within a scene of one unit gave a zero-width,
    'significant' interval (-2.773 [-2.773, -2.773]); now there is none."""
    vocab = Vocabulary.current()
    frame = headline_frame(_tri_rows(seeds=[0]), vocab)
    pairs = paired(frame, vocab)
    row = pairs[(pairs["baseline"] == "texture") & (pairs["metric"] == "acc_completeness_pct")]
    for _, r in row.iterrows():  # per scene and pooled
        assert r["mean_diff"] > 0 and math.isnan(r["lo"]) and math.isnan(r["hi"])
        assert r["note"] == "n/a (1 seed)"
    t1 = table1(frame, vocab).set_index("method")
    assert math.isnan(t1.loc["adaptive", "acc_completeness_pct_lo"])
    assert t1.loc["adaptive", "note"].startswith("n/a (1 seed): ")
    # with two seeds every scene has a spread: an interval, and no note
    pairs = paired(headline_frame(_tri_rows(seeds=[0, 1]), vocab), vocab)
    pooled = pairs[(pairs["scene"] == "all scenes") & (pairs["baseline"] == "texture")].iloc[0]
    assert pooled["lo"] < pooled["mean_diff"] < pooled["hi"] and pooled["note"] == ""


def test_table1_intervals_stay_within_the_metric_range():
    """A t-interval of accuracy near 100 % reaches past 100 (and one of a small rmse below
    0); Table 1 clips it to the declared range, which holds the mean."""
    rows = _tri_rows(seeds=[0, 1, 2])
    rows["accuracy_pct"] = [100.0, 100.0, 100.0, 100.0, 60.0, 100.0] * 4
    t1 = table1(headline_frame(rows, Vocabulary.current()), Vocabulary.current())
    raw = stratified_interval(rows[rows["method"] == "texture"]["accuracy_pct"], rows["scene"][::2])
    assert raw[2] > 100  # the interval as computed
    texture = t1.set_index("method").loc["texture"]
    assert texture["accuracy_pct_hi"] == 100 and texture["accuracy_pct_lo"] == raw[1]


def test_the_interval_is_the_stratified_t_interval_of_a_hand_made_case():
    # one scene, 1..5: mean 3, sd sqrt(2.5), 4 degrees of freedom
    mean, lo, hi, note = stratified_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    half = scipy_stats.t.ppf(0.975, 4) * math.sqrt(2.5 / 5)
    assert (mean, note) == (3.0, "") and (lo, hi) == pytest.approx((3 - half, 3 + half))
    assert (lo, hi) == pytest.approx((1.0367568, 4.9632432))
    # two scenes of unequal spread: variance (1/2)^2 (s_a^2 / 2 + s_b^2 / 4), Welch df
    a, b = np.array([0.0, 2.0]), np.array([10.0, 11.0, 12.0, 13.0])
    x, strata = np.r_[a, b], ["a"] * 2 + ["b"] * 4
    va, vb = (2 / 6) ** 2 * a.var(ddof=1) / 2, (4 / 6) ** 2 * b.var(ddof=1) / 4
    dof = (va + vb) ** 2 / (va**2 / 1 + vb**2 / 3)
    half = scipy_stats.t.ppf(0.975, dof) * math.sqrt(va + vb)
    mean, lo, hi, _ = stratified_interval(x, strata)
    assert mean == pytest.approx(x.mean()) and (lo, hi) == pytest.approx((mean - half, mean + half))
    # no spread within any scene: nothing to measure it by, so no interval
    assert stratified_interval([1.0, 1.0, 5.0, 5.0], ["a", "a", "b", "b"])[3] == "n/a (no spread)"


def test_the_interval_covers_a_known_mean_difference_at_the_grid_shape():
    """4 scenes x 5 seeds of paired differences with scene effects: the 95% interval holds
    the mean over the scenes about 95% of the time (the percentile bootstrap it replaced:
    about 90%); `benchmarks/interval_coverage.py` measures more noise models."""
    rng = np.random.default_rng(0)
    strata = np.repeat(np.arange(4), 5)
    hits = 0
    for _ in range(400):
        effect = 0.3 + rng.normal(0, 1, 4)
        d = effect[strata] + rng.normal(0, 0.5, 20)
        _, lo, hi, _ = stratified_interval(d, strata)
        hits += lo <= effect.mean() <= hi
    assert 0.92 <= hits / 400 <= 0.98


def test_wins_ties_and_losses_follow_the_metric_direction():
    """Over the units both ran: a unit one side lacks (NaN) is left out."""
    strata = np.array(["a"] * 3 + ["b"] * 4)
    d = np.array([1, 2, 1, 5, 4, 5, np.nan])
    r = paired_difference(d, strata, lower_better=False)
    assert (r["n"], r["mean_diff"], r["wins"], r["ties"], r["losses"]) == (6, 3.0, 6, 0, 0)
    assert r["lo"] < 3.0 < r["hi"]
    assert paired_difference(d, strata, lower_better=True)["losses"] == 6
    tied = paired_difference(np.zeros(6), strata[:6], lower_better=False)
    assert (tied["ties"], tied["note"]) == (6, "n/a (no spread)") and math.isnan(tied["lo"])


# --- the sfm exclusion rule ----------------------------------------------------------


def test_table2_of_a_grid_without_the_tri_task():
    """A pairs-only run crashed in Table 2 (KeyError 'acc_completeness_pct') after its rows
    were written, so it had no tables."""
    from bench.report.tables import table2

    rows = []
    for seed in (0, 1):
        cell = dict(scene="s", seed=seed, budget=64, task="pairs", protocol="multiview")
        for method, auc in (("texture", 0.3), ("adaptive", 0.5)):
            rows.append(cell | dict(method=method, auc_10=auc + 0.1 * seed, status="ok"))
    vocab = Vocabulary.current()
    frame = headline_frame(pd.DataFrame(rows), vocab)
    t2 = table2(frame, paired(frame, vocab), vocab).set_index("scene")
    assert t2.loc["all scenes", "diff_pairs_auc_10"] == pytest.approx(0.2)
    assert t2.loc["s", "best_baseline_pairs_auc_10_policy"] == "texture"
    assert math.isnan(t2.loc["s", "oracle_acc_completeness_pct"])


def test_table2_of_a_grid_of_one_peer():
    """`bench run --detector aliked --methods aliked-b` crashed in Table 2 (KeyError
    'scene') after its rows were written: no policy ran beside a peer, so nothing was
    paired."""
    from bench.report.tables import table2

    rows = [
        dict(
            scene="s",
            seed=seed,
            budget=64,
            task="pairs",
            protocol="multiview",
            method="aliked-b",
            auc_10=0.4,
            status="ok",
        )
        for seed in (0, 1)
    ]
    vocab = Vocabulary.current()
    frame = headline_frame(pd.DataFrame(rows), vocab)
    assert paired(frame, vocab).empty
    t2 = table2(frame, paired(frame, vocab), vocab).set_index("scene")
    assert math.isnan(t2.loc["all scenes", "diff_pairs_auc_10"])
    assert t2.loc["s", "best_baseline_pairs_auc_10_policy"] == ""


def test_the_headline_frame_adds_its_columns_without_a_performance_warning():
    """pandas' PerformanceWarning ("highly fragmented") was printed six times in nbv and
    dataset runs: every outer merge leaves a block per column, and the rule's columns were
    then inserted one by one. Rows that already arrive in 120 blocks add none."""
    import warnings

    rows = _sfm_rows(())
    tri = rows.assign(task="tri", acc_completeness_pct=50.0)
    rows = pd.concat([rows, tri], ignore_index=True)
    with warnings.catch_warnings():  # a frame of more than 100 blocks
        warnings.simplefilter("ignore", pd.errors.PerformanceWarning)
        for k in range(120):
            rows[f"extra_{k}"] = float(k)
    with warnings.catch_warnings():
        warnings.simplefilter("error", pd.errors.PerformanceWarning)
        frame = headline_frame(
            with_shares(rows, Vocabulary.current()), Vocabulary.current(), dataset=True
        )
    assert (frame["sfm_exclusion"] == "not applied: a dataset's poses are the truth").all()
    assert len(frame) == 4 and frame["extra_119"].eq(119.0).all()


def _sfm_rows(reference_cells) -> pd.DataFrame:
    """Two seeds of one scene in the sfm task; stock COLMAP maps seed 0, not seed 1, and
    runs in `reference_cells` only."""
    rows = []
    for seed in (0, 1):
        cell = dict(scene="s", seed=seed, task="sfm", protocol="multiview", views=6, status="ok")
        if seed in reference_cells:
            ref = dict(registered_views=6 - 4 * seed, maa=1.0 - 0.8 * seed)
            rows.append(cell | dict(method="colmap", budget=0, **ref))
        for policy, maa in (("texture", 0.4), ("adaptive", 0.6)):
            rows.append(cell | dict(method=policy, budget=64, registered_views=6, maa=maa + seed))
    return mark_reference(pd.DataFrame(rows), Vocabulary.current())


@pytest.mark.parametrize("cells", [(0, 1), (), (1,)])
def test_the_sfm_rule_is_applied_in_all_cells_or_none_and_said(cells):
    """The sfm means depended on which cells stock COLMAP ran in: with it in seed 1 only,
    seed 1 was left out and seed 0 kept. Now the rule is applied only where it ran in
    every cell, and Table 1 says which."""
    vocab = Vocabulary.current()
    frame = headline_frame(_sfm_rows(cells), vocab)
    t1 = table1(frame, vocab).set_index("method")
    if cells == (0, 1):
        assert t1.loc["texture", "sfm_exclusion"] == "applied"
        assert t1.loc["texture", "sfm_maa"] == pytest.approx(0.4)
        assert t1.loc["texture", "sfm_excluded_runs"] == 1
    else:
        missing = 2 - len(cells)
        assert (
            t1.loc["texture", "sfm_exclusion"]
            == f"not applied: colmap did not run in {missing} of 2 cells"
        )
        assert t1.loc["texture", "sfm_maa"] == pytest.approx(0.9)  # both seeds
        pairs = paired_sfm(frame, vocab)
        assert (pairs[pairs["metric"] == "sfm_maa"]["n"] == 2).all()


def test_paired_sfm_compares_every_policy_with_each_budgeted_peer_that_ran():
    """colmap-b, on a learned pool aliked-b, and colmap-tracks-b: each policy minus each
    peer that sees what it sees (texture its image, adaptive other views), by hand."""
    rows = _sfm_rows((0, 1))
    texture = rows[rows["method"] == "texture"]
    peers = [texture.assign(method=p, maa=[0.1, 1.0]) for p in ("aliked-b", "colmap-tracks-b")]
    frame = headline_frame(pd.concat([rows, *peers]), Vocabulary.current())
    pairs = paired_sfm(frame, Vocabulary.current())
    assert "colmap-b" not in set(pairs["baseline"])
    sfm = pairs[(pairs["metric"] == "sfm_maa") & (pairs["scene"] == "s")]
    vs = sfm.set_index(["method", "baseline"])["mean_diff"]
    # seed 1 is left out (stock COLMAP does not map it): adaptive 0.6 - 0.1, texture 0.3
    assert vs["adaptive", "colmap-tracks-b"] == pytest.approx(0.5)
    assert vs["texture", "aliked-b"] == pytest.approx(0.3)
    assert ("adaptive", "aliked-b") not in vs and ("texture", "colmap-tracks-b") not in vs


def test_the_oracle_share_of_a_grid_without_completeness_is_empty():
    rows = pd.DataFrame(
        [
            dict(scene="s", seed=0, budget=64, task="pairs", protocol="multiview", method=m)
            for m in ("oracle", "texture")
        ]
    )
    vocab = Vocabulary.current()
    assert with_shares(rows, vocab)["completeness_vs_oracle_pct"].isna().all()


def test_a_grid_that_scores_sfm_runs_the_reference():
    assert with_reference(("texture", "adaptive"), ("tri", "sfm")) == (
        "texture",
        "adaptive",
        "colmap",
    )
    assert with_reference(("texture",), ("tri",)) == ("texture",)
    assert with_reference(("colmap", "texture"), ("sfm",)) == ("colmap", "texture")


def test_a_dataset_run_with_colmap_keeps_its_sfm_means_and_its_transfer_table(
    medium_entry, quick_results, renders_dir, tmp_path, monkeypatch, capsys
):
    """On a dataset the poses are the truth: nothing is excluded, even where stock COLMAP
    does not map it (adding colmap to the temple run made every sfm mean NaN and removed
    transfer.csv). The default --rendered is the package's snapshot from any folder."""
    ds = export_dataset(medium_entry("table"), tmp_path / "table-ds")
    rendered, out = tmp_path / "r", tmp_path / "d"
    policies = ("random", "texture", "grid", "adaptive")  # three see their own image
    run = RunConfig(render=MEDIUM)

    def ours(rows):  # the rendered grid: the small grid's rows of it (seed 0, B = 64)
        units = (rows["scene"] == "table") & rows["method"].isin(policies)
        return units & (rows["task"] == "sfm") & (rows["protocol"] == "multiview")

    rows_of(quick_results, rendered, ours)
    assert len(read_runs(rendered / "runs.csv")) == len(policies)
    settings = json.loads((rendered / "config.json").read_text())["settings"]
    assert settings == json.loads(json.dumps(run.as_dict()))  # the settings it ran
    argv = ["run", "--dataset", str(ds), "--methods", ",".join([*policies, "colmap"])]
    argv += ["--budget", "64", "--tasks", "sfm", "--protocols", "multiview", "--workers", "1"]
    argv += ["--renders", str(renders_dir), "--results", str(out)]
    assert main([*argv, "--rendered", str(rendered)]) == 0
    # stock COLMAP does not map the dataset, as on the temple (views registered off the
    # truth; at this size it does not map it anyway)
    runs = read_runs(out / "runs.csv")
    runs.loc[runs["method"] == "colmap", ["registered_views", "maa"]] = (2, 0.1)
    (out / "runs.csv").unlink()
    rows = runs.drop(columns=[REFERENCE_MAPS, ROW_CHECKSUM]).to_dict("records")
    append_runs(out / "runs.csv", rows, Vocabulary.current())  # with their checksums
    assert (read_runs(out / "runs.csv")[REFERENCE_MAPS] == 0).all()
    assert main(["plot", "--results", str(out), "--rendered", str(rendered)]) == 0
    t1 = pd.read_csv(out / "table1.csv").set_index("method")
    sfm = runs[runs["method"] == "texture"]["maa"]
    assert t1.loc["texture", "sfm_maa"] == pytest.approx(sfm.mean())
    assert t1.loc["texture", "sfm_exclusion"] == "not applied: a dataset's poses are the truth"
    summary = pd.read_csv(out / "transfer.csv")
    assert summary["methods"].tolist() == [3]
    # from another folder, the default --rendered is the package's published snapshot
    capsys.readouterr()
    monkeypatch.chdir(tmp_path)
    assert not (tmp_path / "results").exists()
    assert main(["plot", "--results", str(out)]) == 0
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "no rendered results" not in err
    assert "share no budget (the datasets ran 64; the rendered results 128" in err  # it was read
    assert main(["plot", "--results", str(out), "--rendered", "nowhere"]) == 0
    missing = "no transfer.csv: no rendered results to compare with (nowhere/runs.csv is missing"
    assert missing in capsys.readouterr().err


def test_the_front_end_cost_reads_its_tasks_from_the_vocabulary():
    """The posed and the pose-free task are the headline task and the first task granted
    the images only of the rows' vocabulary, whatever they are named."""
    from bench.report.tables import frontend_cost
    from bench.vocabulary import Method, Task

    tasks = {
        "tri": Task("tri", "rig", needs=(), metrics=()),
        "free": Task("free", "images", needs=(), metrics=(), peers=True),
    }
    vocab = Vocabulary({"texture": Method("texture", "Texture", "baseline")}, tasks)
    assert vocab.posefree_task == "free"
    df = pd.DataFrame(
        [
            {"scene": "table", "seed": s, "budget": 64, "method": "texture", "task": task}
            | {"protocol": "multiview", "detect_ms": ms, "signals_ms": 0.0, "select_ms": 0.0}
            for s in (0, 1)
            for task, ms in (("tri", 10.0), ("free", 30.0))
        ]
    )
    row = frontend_cost(df, vocab).iloc[0]
    assert row["frontend_ms"] == 10.0 and row["frontend_ms_posefree"] == 30.0
    assert row["posefree_to_posed"] == 3.0


# --- a task is one declaration -----------------------------------------------------


def test_a_task_and_a_metric_declared_once_are_in_every_table_figure_and_the_page(
    tmp_path, monkeypatch
):
    """A metric is declared once (`Metric`: range, direction, title) and a task names it
    (`Task.metrics`, `headline`): a new task with a metric of its own where lower is better
    is in Table 1, the paired tables, Table 2, the per-scene table, the figures, the page
    and the runs contract (its range), with no other change."""
    from bench.report import figures
    from bench.report.page import results_page
    from bench.report.write import write_tables
    from bench.unit.tasks import TASK_RUNNERS, TaskRunner, register
    from bench.vocabulary import METRICS, TASKS, Metric, Task, declare_metric

    declare_metric(Metric("score", (0.0, 1.0), lower_better=True, title="Toy score"))
    toy = Task("toy", "images", needs=("score",), metrics=("score",), headline=("score",))
    register(TaskRunner(toy, reconstruct=None, evaluate=None))
    try:
        vocab = Vocabulary.current()
    finally:
        TASK_RUNNERS.pop("toy"), TASKS.pop("toy"), METRICS.pop("score")
    assert "toy" not in Vocabulary.current().tasks  # the other tests see the package's
    assert vocab.range_of("score") == (0.0, 1.0) and "toy_score" in vocab.lower_better()
    rows = []
    for seed in range(3):
        cell = dict(scene="s", seed=seed, budget=256, protocol="multiview", status="ok")
        for policy, completeness, score in (
            ("adaptive", 50.0, 0.1),
            ("texture", 45.0, 0.4),
            ("random", 30.0, 0.2),
        ):
            tri = dict(acc_completeness_pct=completeness + seed, accuracy_pct=80.0 + seed)
            rows.append(cell | dict(method=policy, task="tri", **tri))
            rows.append(cell | dict(method=policy, task="toy", score=score + 0.01 * seed))
    (tmp_path / VOCABULARY).write_text(vocab.to_json())
    assert read_vocabulary(tmp_path).tasks["toy"] == toy  # recorded as declared
    df = with_shares(pd.DataFrame(rows), vocab)
    t1 = write_tables(df, tmp_path, vocab)[0].set_index("method")
    assert t1.loc["adaptive", "toy_score"] == pytest.approx(0.11)
    pairs = pd.read_csv(tmp_path / "paired.csv").set_index(["scene", "baseline", "metric"])
    # adaptive's score is the lowest in every unit: a win, lower being better
    won = pairs.loc[("all scenes", "random", "toy_score"), ["n", "wins", "losses"]]
    assert won.tolist() == [3, 3, 0]
    t2 = pd.read_csv(tmp_path / "table2.csv").set_index("scene")
    assert t2.loc["all scenes", "best_baseline_toy_score_policy"] == "random"  # the lower
    assert t2.loc["all scenes", "diff_toy_score"] == pytest.approx(-0.1)
    assert "toy_score" in pd.read_csv(tmp_path / "table_scenes.csv")
    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.update(fig=fig))
    figures.figure3(t1.reset_index(), vocab, tmp_path / "figure3")
    assert "Toy score" in [ax.get_title() for ax in drawn["fig"].axes]
    page = results_page(tmp_path, df)
    assert "| adaptive (views) | random (image) | toy_score | 3 |" in page


@pytest.mark.parametrize(
    "section, field", [("tasks", "headline"), ("methods", "kind"), ("", "metrics")]
)
def test_a_folder_recorded_by_an_older_bench_is_refused_and_upgraded(
    tmp_path, capsys, section, field
):
    """A `vocabulary.json` that lacks a field the report reads (a task's headline, a
    method's kind, the metrics) would give wrong tables: refused in one line naming
    `bench upgrade`, which records the package's declarations of the same names."""

    data = json.loads(Vocabulary.current().to_json())
    for entry in data[section].values() if section else [data]:
        entry.pop(field)
    (tmp_path / VOCABULARY).write_text(json.dumps(data))
    with pytest.raises(BenchError, match=f"lacks .*{field}.*`bench upgrade --results {tmp_path}`"):
        read_vocabulary(tmp_path)
    assert main(["upgrade", "--results", str(tmp_path)]) == 0
    assert f"declared as this bench does ({section + ' field ' if section else ''}{field}" in (
        capsys.readouterr().out
    )
    assert read_vocabulary(tmp_path) == Vocabulary.current()
    assert main(["upgrade", "--results", str(tmp_path)]) == 0
    assert "up to date" in capsys.readouterr().out
