"""What a selection sees (issue 53): `image` (its own view's) or `views` (other views,
through a first pass), derived from each method's kind and the signals it reads, recorded
in `vocabulary.json` and shown in Table 1."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from bench.binding import read_vocabulary
from bench.frontend.signals import GEOMETRIC
from bench.report.tables import headline_frame, table1
from bench.results import VOCABULARY
from bench.unit.declared import package_vocabulary
from bench.vocabulary import (
    IMAGE,
    REFERENCE_MAPS,
    TRUTH,
    VIEW_SIGNALS,
    VIEWS,
    Method,
    Vocabulary,
    sees,
)

OWN_IMAGE = (
    *("random", "texture", "grid", "response", "scale", "ssc", "quadtree", "all"),
    *("colmap", "colmap-b", "colmap-soft-b", "aliked-b", "disk-b", "response@colmap-soft-b"),
)
OTHER_VIEWS = (
    *("adaptive", "adaptive-fast", "cross-view", "learned", "track-first", "adaptive-loop"),
    *("cross-view@colmap-soft-b", "track-first@colmap-soft-b", "colmap-tracks-b"),
)


def test_every_method_sees_its_image_or_the_other_views_as_it_reads():
    vocab = package_vocabulary()
    assert {m: vocab.sees(m) for m in OWN_IMAGE} == dict.fromkeys(OWN_IMAGE, IMAGE)
    assert {m: vocab.sees(m) for m in OTHER_VIEWS} == dict.fromkeys(OTHER_VIEWS, VIEWS)
    assert vocab.sees("oracle") == TRUTH
    assert VIEW_SIGNALS == GEOMETRIC  # the signals that read the geometry between views


def test_a_per_view_policy_sees_the_views_once_it_reads_one_of_their_signals():
    plain = Method("p", "p", "contender", reads=("texture", "distinctiveness"))
    assert sees(plain) == IMAGE
    for signal in VIEW_SIGNALS:
        assert sees(Method("p", "p", "contender", reads=("texture", signal))) == VIEWS


def test_sees_is_recorded_in_the_vocabulary_and_derived_for_an_older_record(tmp_path):
    vocab = Vocabulary.current()
    (tmp_path / VOCABULARY).write_text(vocab.to_json())
    recorded = json.loads((tmp_path / VOCABULARY).read_text())["methods"]
    assert recorded["track-first"]["sees"] == VIEWS and recorded["colmap-b"]["sees"] == IMAGE
    assert read_vocabulary(tmp_path).seen == vocab.seen
    for entry in recorded.values():  # a record written before `sees`: derived alike
        entry.pop("sees")
    older = Vocabulary.from_json(json.dumps({**json.loads(vocab.to_json()), "methods": recorded}))
    assert not older.seen and all(older.sees(m) == vocab.sees(m) for m in vocab.methods)


def test_table1_says_what_each_method_sees():
    vocab = Vocabulary.current()
    rows = [
        dict(scene=s, seed=0, method=m, budget=128, task="sfm", protocol="multiview", maa=v)
        for s in ("a", "b")
        for m, v in (("response", 0.2), ("track-first", 0.8), ("colmap-b", 0.3))
    ]
    t1 = table1(headline_frame(pd.DataFrame(rows), vocab), vocab).set_index("method")
    assert t1["sees"].to_dict() == {"response": IMAGE, "track-first": VIEWS, "colmap-b": IMAGE}


def _sfm_rows() -> pd.DataFrame:
    """sfm mAA in 4 scenes x 3 seeds: track-first 0.8 ahead of colmap-tracks-b 0.7 and of
    every own-image method; response 0.2 and grid 0.1 behind colmap-b 0.3."""
    values = {"response": 0.2, "grid": 0.1, "colmap-b": 0.3}
    values |= {"track-first": 0.8, "cross-view": 0.5, "colmap-tracks-b": 0.7}
    return pd.DataFrame(
        dict(scene=s, seed=k, method=m, budget=128, task="sfm", protocol="multiview", maa=v)
        | dict(maa=v + 0.01 * k * (i + 1) + 0.003 * k * (m in ("track-first", "grid")))
        for i, s in enumerate("abcd")
        for k in range(3)
        for m, v in values.items()
    )


def test_each_category_is_judged_against_its_own_peer_and_said_naming_it():
    from bench.report.categories import category_verdicts, headline
    from bench.report.tables import paired_sfm

    vocab = Vocabulary.current()
    frame = headline_frame(_sfm_rows(), vocab)
    v = category_verdicts(frame, vocab).set_index("sees")
    assert v.loc[IMAGE, ["policy", "peer", "verdict"]].tolist() == ["response", "colmap-b", "below"]
    assert v.loc[VIEWS, ["policy", "peer", "verdict"]].tolist() == [
        "track-first",
        "colmap-tracks-b",
        "above",
    ]
    assert v.loc[VIEWS, "mean_diff"] == pytest.approx(0.103) and v.loc[VIEWS, "n"] == 12
    said = headline(category_verdicts(frame, vocab))
    assert "see their own image (`image`)" in said and "see other views (`views`)" in said
    pairs = paired_sfm(frame, vocab)
    judged = set(zip(pairs["method"], pairs["baseline"]))
    assert ("track-first", "colmap-tracks-b") in judged and ("response", "colmap-b") in judged
    assert ("track-first", "colmap-b") not in judged and ("grid", "colmap-tracks-b") not in judged
    t1 = table1(frame, vocab).set_index("method")["sfm_maa_tier"]
    assert t1["track-first"] == 1 and t1["colmap-b"] == 1  # each the best of its category


def test_a_verdict_sentence_writes_its_numbers_in_one_format():
    """Means with three decimals, the difference and its bounds signed (it read
    `-0.0717 [-0.219, 0.0761]` beside means of three significant figures)."""
    from bench.report.categories import verdict_sentence

    row = dict(sees=IMAGE, budget=256, metric="sfm_maa", policy="scale", policy_mean=0.392333)
    row |= dict(peer="colmap-b", peer_mean=0.464, mean_diff=-0.0716667, lo=-0.219451)
    row |= dict(hi=0.076118, note="", wins=5, ties=10, losses=5, n=20, verdict="tied")
    said = verdict_sentence(pd.Series(row))
    assert "`scale` (0.392), against" in said and "`colmap-b` (0.464)" in said
    assert ": -0.072 [-0.219, +0.076], 5/10/5 over 20 runs, tied." in said


def test_a_partly_run_policy_is_judged_on_its_own_cells_and_never_named_best():
    """A policy run on one easy cell (a user's module added to a snapshot, say) is not
    the category's leader over the others' cells, nor tiered over them; asked for by
    name, it is judged on the cells both it and the peer have, and the sentence says so."""
    from bench.report.categories import category_verdicts, verdict_sentences

    vocab = Vocabulary.current()
    rows = _sfm_rows()
    easy = rows[(rows["method"] == "response") & (rows["scene"] == "a") & (rows["seed"] == 0)]
    rows = pd.concat([rows, easy.assign(method="peak-scale", maa=0.95)], ignore_index=True)
    frame = headline_frame(rows, vocab)
    v = category_verdicts(frame, vocab).set_index("sees")
    assert v.loc[IMAGE, "policy"] == "response"  # not peak-scale's one cell at 0.95
    mine = category_verdicts(frame, vocab, "peak-scale").set_index("sees").loc[IMAGE]
    assert (mine["n"], mine["policy_runs"], mine["peer_runs"]) == (1, 1, 12)
    assert mine["peer_mean"] == pytest.approx(0.3)  # colmap-b on that one cell, not its 12
    said = verdict_sentences(category_verdicts(frame, vocab, "peak-scale"))[0]
    assert (
        "over 1 runs" in said and "(on the 1 cells both ran: `peak-scale` 1, `colmap-b` 12)" in said
    )
    t1 = table1(frame, vocab).set_index("method")["sfm_maa_tier"]
    assert np.isnan(t1["peak-scale"]) and t1["colmap-b"] == 1


def test_a_policy_whose_peer_did_not_run_is_said_to_be_judged_by_no_verdict():
    from bench.report.categories import category_verdicts, unjudged

    vocab = Vocabulary.current()
    rows = _sfm_rows()
    rows = rows[rows["method"] != "colmap-tracks-b"]
    said = unjudged(vocab, set(rows["method"]))
    assert len(said) == 1 and "`track-first`" in said[0] and "`cross-view`" in said[0]
    assert said[0].endswith(
        "(`views`) judged by no verdict: no peer of the category ran; add `colmap-tracks-b` "
        "to --methods"
    )
    assert set(category_verdicts(headline_frame(rows, vocab), vocab)["sees"]) == {IMAGE}
    assert unjudged(vocab, set(_sfm_rows()["method"])) == []


def test_a_verdict_counts_only_the_cells_the_reference_maps():
    """sfm's exclusion rule: a cell stock COLMAP with all features does not map measures
    nothing, and no verdict counts it (`bench.report.tables.solvable`)."""
    from bench.report.categories import category_verdicts

    vocab = Vocabulary.current()
    rows = _sfm_rows().assign(**{REFERENCE_MAPS: 1})
    rows.loc[(rows["scene"] == "a") & (rows["seed"] == 0), REFERENCE_MAPS] = 0
    v = category_verdicts(headline_frame(rows, vocab), vocab).set_index("sees")
    assert v.loc[IMAGE, "n"] == v.loc[VIEWS, "n"] == 11  # of 12 cells
    assert v.loc[IMAGE, "policy_runs"] == v.loc[IMAGE, "peer_runs"] == 11
