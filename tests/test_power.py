"""Reliability, ceiling, real-to-real baseline, sign agreement and tiers on hand-made cases
with known answers (`bench.report.power`)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from bench.report.power import (
    ceiling,
    half_splits,
    holm,
    lengthening,
    real_to_real,
    sign_agreement,
    spearman_brown,
    split_half,
    tiers,
)


def test_spearman_brown_and_the_ceiling():
    assert spearman_brown(0.5) == pytest.approx(2 / 3)
    assert spearman_brown(1.0) == 1.0 and spearman_brown(0.0) == 0.0
    assert math.isnan(spearman_brown(-1.0))
    assert ceiling(0.64, 1.0) == pytest.approx(0.8)
    assert math.isnan(ceiling(0.5, -0.1))
    assert lengthening(0.5, 0.8) == pytest.approx(4.0)  # 4 x the units: 4r/(1+3r) = 0.8
    assert spearman_brown(1 / 3) == pytest.approx(0.5)  # doubling 1/3 gives 0.5
    assert lengthening(1 / 3, 0.5) == pytest.approx(2.0)


def test_half_splits_enumerate_each_distinct_split_once():
    assert len(half_splits(4)) == 3  # {0,1}|{2,3}, {0,2}|{1,3}, {0,3}|{1,2}
    assert len(half_splits(5)) == 10  # C(5, 2): the halves differ in size
    assert len(half_splits(30)) == 200  # too many: random ones
    assert all(m.sum() == 15 for m in half_splits(30))


def test_split_half_of_four_units_has_its_known_reliability():
    # the three splits' halves give tau-b 0.5, 1 and 0.5: r = 2/3, reliability 0.8
    values = pd.DataFrame(
        [[3, 2, 1], [3, 1, 2], [3, 2, 1], [2, 3, 1]], columns=["x", "y", "z"], dtype=float
    )
    r, rel = split_half(values)
    assert r == pytest.approx(2 / 3) and rel == pytest.approx(0.8)
    same = pd.DataFrame([[3, 2, 1], [6, 5, 4]], columns=["x", "y", "z"], dtype=float)
    assert split_half(same) == (1.0, 1.0)
    assert all(math.isnan(v) for v in split_half(same.iloc[:1]))


def test_real_to_real_ranks_the_other_sets_against_each():
    means = pd.DataFrame(
        [[3, 2, 1], [3, 2, 1], [3, 1, 2]], index=["A", "B", "C"], columns=["a", "b", "c"]
    )
    base = real_to_real(means.astype(float), lower_better=False)
    assert base["C"] == pytest.approx(1 / 3)  # others rank a, b, c; C ranks a, c, b
    assert base["A"] == pytest.approx(2 / math.sqrt(6))  # others: a 1, b 2.5, c 2.5 (a tie)
    flipped = real_to_real(-means.astype(float), lower_better=True)
    assert flipped.to_dict() == pytest.approx(base.to_dict())


def test_sign_agreement_counts_the_decided_methods_only():
    a = pd.Series({"m1": 0.2, "m2": -0.1, "m3": 0.0, "m4": 0.3})
    b = pd.Series({"m1": 0.1, "m2": 0.1, "m3": 0.5, "m4": 0.2})
    assert sign_agreement(a, b) == (2, 3)  # m3 has no sign on one side


def test_holm_adjusts_step_down_and_keeps_the_order():
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])


def test_tiers_join_methods_that_cannot_be_told_apart():
    rng = np.random.default_rng(0)
    base = rng.uniform(0.4, 0.6, 10)
    values = pd.DataFrame({"a": base, "b": base, "c": base - 0.3})
    # a and b never differ (p 1); c is below both in all ten units (exact p 2/1024, x3 Holm)
    assert tiers(values, lower_better=False).to_dict() == {"a": 1, "b": 1, "c": 2}
    assert tiers(-values, lower_better=True).to_dict() == {"a": 1, "b": 1, "c": 2}
    few = values.iloc[:4]  # four units: the smallest two-sided p is 1/8, never below 0.05
    assert set(tiers(few, lower_better=False)) == {1}


def test_a_transfer_row_carries_its_power_with_known_values():
    from bench.report.transfer import power

    cols = ["x", "y", "colmap-b"]
    real = pd.DataFrame([[3, 2, 1], [3, 1, 2], [3, 2, 1], [2, 3, 1]], columns=cols, dtype=float)
    ref = pd.DataFrame([[1, 2, 3], [2, 3, 4]], columns=cols, dtype=float)
    sets = pd.DataFrame(
        [real.mean().to_list(), [3, 2, 1], [1, 3, 2]], index=["this", "B", "C"], columns=cols
    )
    out = power(real, ref, sets, "this", cols, lower_better=False)
    assert out["rel_dataset"] == pytest.approx(0.8) and out["rel_rendered"] == 1.0
    assert out["ceiling"] == pytest.approx(math.sqrt(0.8))
    # others' mean ranks x 2, y 1.5, colmap-b 2.5; this set ranks x, y, colmap-b: (x, y) is
    # the one discordant pair of three
    assert out["tau_photos"] == pytest.approx(1 / 3)
    # this set: x +1.5, y +0.75 over colmap-b; renders: x -2, y -1; others: x +0.5, y +1
    assert (out["signs_agree"], out["signs_decided"]) == (0, 2)
    assert (out["signs_agree_photos"], out["signs_decided_photos"]) == (2, 2)


def test_table1_tiers_each_budget_apart_and_leave_references_out():
    from pathlib import Path

    from bench.binding import read_vocabulary
    from bench.report.tables import tier_column, with_tiers

    vocab = read_vocabulary(Path(__file__).resolve().parents[1] / "results" / "published")
    base = np.random.default_rng(0).uniform(0.4, 0.6, 10)
    values = {"texture": base, "grid": base, "random": base - 0.3, "oracle": base + 0.3}
    rows = pd.DataFrame(
        [
            {"scene": "s", "seed": k, "method": m, "budget": b, "pairs_auc_10": v[k] * b / 256}
            for b in (128, 256)
            for m, v in values.items()
            for k in range(10)
        ]
    )
    t = pd.DataFrame([{"method": m, "budget": b} for b in (128, 256) for m in values])
    got = with_tiers(t, rows, vocab)
    tiers = dict(zip(zip(got["method"], got["budget"]), got[tier_column("pairs_auc_10")]))
    for b in (128, 256):
        assert (tiers["texture", b], tiers["grid", b], tiers["random", b]) == (1, 1, 2)
        assert math.isnan(tiers["oracle", b])  # a reference: shown, never tiered


def test_the_verdict_says_whether_the_renders_predict_a_set_as_well_as_the_photographs():
    from bench.report.transfer import verdicts

    row = dict(dataset="d", rendered_views=6, matched=True, budget=256, tau_lo=0.1, tau_hi=0.8)
    row |= dict(rel_rendered=0.9, rel_dataset=0.8, ceiling=math.sqrt(0.72), tau_note="")
    summary = pd.DataFrame(
        [
            row | dict(metric="sfm_maa", kendall_tau=0.5, tau_photos=0.3),
            row | dict(metric="pairs_auc_10", kendall_tau=0.5, tau_photos=0.9),
            row | dict(matched=False, metric="sfm_maa", kendall_tau=0.0, tau_photos=0.3),
        ]
    )
    sfm, pairs = verdicts(summary, 256)  # one sentence per set and task, matched regime
    assert sfm.startswith("d, sfm_maa, B = 256, against the 6-view renders: tau 0.50 [0.10, 0.80]")
    assert "(1: the renders order its methods as the set does, 0: no relation" in sfm
    assert "reliabilities (0.90 renders, 0.80 this set) cap any tau at the ceiling 0.85" in sfm
    assert sfm.endswith(
        "the other sets predict it at 0.30: the renders predict it as well as the other "
        "photographs (theirs lies within the interval)."
    )
    assert "at 0.90: the renders predict it less well than the other photographs." in pairs


def test_the_renders_predict_a_set_less_well_or_better_only_outside_the_interval():
    """It said "less well" wherever the other sets' tau was above the renders' point
    estimate, even inside its interval (templeSparseRing: 0.73 [0.33, 1.00] against 0.78)."""
    from types import SimpleNamespace

    from bench.report.transfer import prediction

    def said(photos, tau=0.73, lo=0.33, hi=1.0):
        return prediction(SimpleNamespace(kendall_tau=tau, tau_lo=lo, tau_hi=hi, tau_photos=photos))

    assert said(0.78) == said(0.40) == said(0.33) == "as well as"
    assert said(0.20) == "better than" and said(0.9, hi=0.85) == "less well than"
    assert said(math.nan) == "n/a" and said(0.5, tau=math.nan) == "cannot tell"


def test_with_one_set_the_verdict_still_says_what_its_tau_means_and_its_ceiling():
    """With one set `tau_photos` is empty and no sentence was written; an interval above
    its ceiling had no word."""
    from bench.report.transfer import verdicts

    row = dict(dataset="d", rendered_views=21, matched=True, budget=256, metric="sfm_maa")
    row |= dict(kendall_tau=0.7, tau_lo=0.4, tau_hi=1.0, tau_note="", tau_photos=math.nan)
    row |= dict(rel_rendered=0.95, rel_dataset=0.94, ceiling=math.sqrt(0.95 * 0.94))
    (line,) = verdicts(pd.DataFrame([row]), 256)
    assert "tau 0.70 [0.40, 1.00]" in line and "ceiling 0.94 (the interval reaching above" in line
    assert line.endswith("no other set to compare with (the baseline needs two sets).")
    (why,) = verdicts(pd.DataFrame([row | dict(kendall_tau=math.nan, tau_note="no tau: 5")]), 256)
    assert ": no tau: 5; the split-half reliabilities (0.95 renders, 0.94 this set)" in why
    (own,) = verdicts(pd.DataFrame([row | dict(sees="image")]), 256)  # a category's ranking
    assert own.startswith("d, sfm_maa among the selections that see `image`, B = 256, against")


def test_the_tiers_claim_holds_how_many_units_tell_any_two_methods_apart():
    from bench.report.power import min_units

    assert (min_units(2), min_units(5), min_units(13)) == (6, 9, 12)
    values = pd.DataFrame({"a": np.arange(8) + 1.0, "b": np.zeros(8)})  # 2 methods, 8 units
    assert tiers(values, lower_better=False).to_dict() == {"a": 1, "b": 2}
    assert set(tiers(values.iloc[:5], lower_better=False)) == {1}  # 5 < 6 units: one tier


def test_holms_correction_merges_a_tier_the_raw_p_values_would_split():
    """a exceeds b in 7 of 10 units (signed ranks -1, -2, -3, +4 ... +10: exact p 0.027),
    and c is b: raw, a stands apart from b and c (p 0.027 < 0.05); Holm's x 3 gives 0.082,
    one tier."""
    b = np.linspace(0.2, 0.5, 10)
    d = np.arange(1, 11) / 100 * np.r_[-1, -1, -1, np.ones(7)]
    values = pd.DataFrame({"a": b + d, "b": b, "c": b})
    assert tiers(values, lower_better=False).to_dict() == {"a": 1, "b": 1, "c": 1}


def test_a_zero_on_either_side_leaves_the_method_undecided():
    a = pd.Series({"m1": 0.2, "m2": -0.1, "m3": 0.3})
    b = pd.Series({"m1": 0.1, "m2": 0.0, "m3": 0.2})
    assert sign_agreement(a, b) == (2, 2)  # m2 has no sign on the second side
    assert sign_agreement(b, a) == (2, 2)  # nor on the first


def test_the_photographs_sign_baseline_leaves_the_set_itself_out():
    """This set: x +3 over colmap-b; the others: x -0.5 and +0.2 (mean -0.15, against
    this set's sign), y +1 everywhere. With this set in the others' mean, x would agree."""
    from bench.report.transfer import power

    cols = ["x", "y", "colmap-b"]
    real = pd.DataFrame([[4, 2, 1], [4, 2, 1]], columns=cols, dtype=float)
    sets = pd.DataFrame(
        [[4, 2, 1], [0.5, 2, 1], [1.2, 2, 1]], index=["this", "B", "C"], columns=cols
    )
    out = power(real, real, sets, "this", cols, lower_better=False)
    assert (out["signs_agree_photos"], out["signs_decided_photos"]) == (1, 2)


def _pairs_rows(scene: str, cells: list[list[float]], methods: list[str]) -> list[dict]:
    """Hand-made `ok` pairs rows at B = 256: one per (cell, method), auc_10 its value."""
    return [
        {"scene": scene, "seed": k, "method": m, "budget": 256, "task": "pairs"}
        | {"protocol": "none", "render_key": "r", "prediction_hash": "p"}
        | {"evaluation_hash": "e", "status": "ok", "failure": "", "invocation": "i"}
        | {"wall_ms": 1.0, "auc_10": v, "maa_pairs": v, "pairs_scored": 15}
        for k, row in enumerate(cells)
        for m, v in zip(methods, row)
    ]


def test_transfer_gives_each_side_its_own_reliability(tmp_path):
    """The renders' cells rank the methods the same in every unit (reliability 1); the
    photographs' are the four units of reliability 0.8 above."""
    import shutil
    from pathlib import Path

    from bench.binding import read_vocabulary
    from bench.report.transfer import transfer
    from bench.runs import append_runs

    published = Path(__file__).resolve().parents[1] / "results" / "published"
    for name in ("vocabulary.json", "config.json"):
        shutil.copy(published / name, tmp_path / name)
    vocab = read_vocabulary(tmp_path)
    methods = ["texture", "grid", "random"]
    rendered = [[0.3, 0.2, 0.1], [0.6, 0.5, 0.4], [0.3, 0.2, 0.1], [0.6, 0.5, 0.4]]
    append_runs(tmp_path / "runs.csv", _pairs_rows("table", rendered, methods), vocab)
    photos = [[0.3, 0.2, 0.1], [0.3, 0.1, 0.2], [0.3, 0.2, 0.1], [0.2, 0.3, 0.1]]
    summary, _ = transfer(pd.DataFrame(_pairs_rows("set", photos, methods)), vocab, tmp_path)
    (row,) = summary.to_dict("records")
    assert row["rel_rendered"] == 1.0 and row["rel_dataset"] == pytest.approx(0.8)


def test_a_reliability_at_or_below_zero_says_why_nothing_can_be_told_and_no_nan():
    """kitti-seq2's sfm `views` ranking: a split-half reliability of -0.25 left the ceiling
    undefined; the sentence said 'ceiling nan' and the verdict 'as well as the others'."""
    from bench.report.transfer import CANNOT_TELL, prediction, verdicts

    row = dict(dataset="d", rendered_views=6, matched=True, budget=256, metric="sfm_maa")
    row |= dict(kendall_tau=-0.25, tau_lo=-0.69, tau_hi=0.16, tau_note="", tau_photos=-0.18)
    row |= dict(rel_rendered=0.88, rel_dataset=-0.25, ceiling=math.nan)
    (line,) = verdicts(pd.DataFrame([row]), 256)
    assert "nan" not in line
    assert "(0.88 renders, -0.25 this set) allow no ceiling: a reliability at or below 0" in line
    assert prediction(pd.DataFrame([row]).iloc[0]) == CANNOT_TELL
    assert line.endswith(f"the other sets predict it at -0.18: {CANNOT_TELL}.")
