"""The own-image matchability selector: its features on hand-made candidates, its labels
against the oracle's matchable tracks, its training and its model file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench import BenchError
from bench.camera import Camera
from bench.evaluation.oracle import matchable_tracks
from bench.evaluation.truth import scene_truth
from bench.frontend.features import Candidates, DetectorConfig
from bench.frontend.geometry import SignalConfig
from bench.frontend.matchability import (
    EVERY_TYPE,
    FEATURES,
    SHIPPED_MODEL,
    MatchableConfig,
    features,
    model_for,
    predicted_order,
    read_models,
)
from bench.frontend.policies import PolicyInput, select
from bench.frontend.stage import front_end
from bench.frontend.views import View
from bench.harness.grid import BenchConfig
from bench.harness.matchability import fit, labels, precision_at, train_matchability
from bench.memo import last_call
from bench.unit.config import RunConfig
from tests.conftest import MEDIUM


def _view(width=100, height=80) -> View:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    image[:, :50] = 128  # a flat left half
    cam = Camera(width, height, 100.0, 100.0, width / 2, height / 2, np.eye(3), np.zeros(3))
    return View(0, "v.png", image, cam)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float32)
    return v / np.linalg.norm(v)


def test_each_feature_on_hand_made_candidates():
    a, b, c, d = (_unit(v) for v in ([1, 0, 0, 0], [0, 1, 0, 0], [1, 0.01, 0, 0], [0, 0, 1, 0]))
    cand = Candidates(
        xy=np.array([[10.0, 40.0], [10.0, 40.0], [75.0, 40.0], [90.0, 5.0]]),
        size=np.array([4.0, 4.0, 8.0, 2.0]),
        angle=np.array([0.0, 90.0, 0.0, 0.0]),
        response=np.array([0.01, 0.01, 0.1, 0.001]),
        descriptors=np.stack([a, b, c, d]),
    )
    X = dict(zip(FEATURES, features(PolicyInput(_view(), cand, None)).T))
    assert np.allclose(X["log_sigma"], np.log2([2, 2, 4, 1]))
    assert np.allclose(X["log_response"], [-2, -2, -1, -3])
    assert X["twins"].tolist() == [2, 2, 1, 1]  # two orientations at one location
    assert np.allclose(X["border_scale"], [2.5, 2.5, 25 / 8, 2.5])
    assert X["contrast"][0] < 0.01 < 0.5 < X["contrast"][2]  # flat half, noisy half
    # `a`'s nearest elsewhere is `c` (almost the same descriptor), its twin `b` is not counted
    assert X["distinct"][0] < 0.05 and X["distinct"][2] < 0.05
    assert 0.9 < X["distinct"][1] <= 1.0 and 0.9 < X["distinct"][3] <= 1.0


def test_twins_and_distinct_are_the_dense_definition_at_the_radius_and_across_blocks(
    monkeypatch,
):
    import bench.frontend.matchability as m
    from bench.frontend.features import descriptor_distances

    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 40, (300, 2)).astype(np.float32)
    xy[1] = xy[0]  # a second orientation at one location
    xy[3] = xy[2] + np.float32([2.0, 0.0])  # exactly at the radius: not a twin
    xy[5] = xy[4] + np.float32([1.9999, 0.0])  # just inside it
    desc = rng.integers(0, 255, (300, 16)).astype(np.float32)
    near = np.linalg.norm(xy[:, None] - xy[None], axis=2) < m.TWIN_PX  # the definition
    D = descriptor_distances(desc, desc)
    D[near] = np.inf
    D.sort(1)
    monkeypatch.setattr(m, "ROWS", 64)  # several blocks
    twins, distinct = m._own_neighbours(xy, desc)
    assert twins.tolist() == near.sum(1).tolist() and twins[[0, 1, 2, 3, 5]].min() >= 1
    assert twins[0] >= 2 and twins[4] >= 2 and not near[2, 3]
    np.testing.assert_array_equal(distinct, D[:, 0] / D[:, 1])


class _Fixed:
    def __init__(self, p):
        self.p = np.asarray(p, float)

    def predict_proba(self, X):
        return np.stack([1 - self.p, self.p], 1)


def test_the_order_is_by_predicted_probability_ties_by_index():
    assert predicted_order(_Fixed([0.2, 0.9, 0.2, 0.5]), np.zeros((4, 6))).tolist() == [1, 3, 0, 2]
    assert predicted_order(_Fixed([]), np.zeros((0, 6))).tolist() == []


def test_precision_at_b_on_a_hand_made_order():
    y = np.array([0, 2, 1, 0, 3])
    assert precision_at(np.array([1, 2, 0, 3, 4]), y, 2) == 1.0
    assert precision_at(np.array([0, 3, 1, 2, 4]), y, 4) == 0.5


@pytest.fixture(scope="module")
def labelled(medium_entry, renders_dir):
    return labels(medium_entry("table"), RunConfig(render=MEDIUM), renders_dir, "table")


def test_a_label_counts_views_where_the_oracle_finds_a_true_match(
    labelled, medium_entry, renders_dir
):
    entry = medium_entry("table")
    fe = front_end(entry, DetectorConfig(), SignalConfig(), renders_dir / "frontend")
    truth = scene_truth(entry, [v.camera for v in fe.views], [v.name for v in fe.views], fe.pools)
    track = matchable_tracks(truth, fe.pools, RunConfig().backend.ratio)
    views = np.concatenate([np.full(len(t), v) for v, t in enumerate(track)])
    span = {
        t: len(set(views[np.concatenate(track) == t])) for t in np.unique(np.concatenate(track))
    }
    y = np.concatenate([v[1] for v in labelled])
    assert y.max() <= len(fe.views) - 1 and (y > 0).sum() > 20
    spans = np.array([span[t] for t in np.concatenate(track)])
    assert np.all(spans[y > 0] >= 2)  # matchable somewhere: on a track of two views or more
    assert np.all(y[spans == 1] == 0)  # alone on its track: matchable nowhere
    assert all(len(X) == len(y) and np.isfinite(X).all() for X, y, _ in labelled)


def test_a_fit_is_deterministic(labelled):
    X = np.concatenate([v[0] for v in labelled])
    a, b = (fit(labelled).predict_proba(X)[:, 1] for _ in range(2))
    assert np.array_equal(a, b) and np.ptp(a) > 0


def test_training_holds_each_scene_type_out_and_its_model_selects_by_the_contract(
    medium_entry, renders_dir, tmp_path
):
    for s in ("table", "facade"):
        medium_entry(s)
    out = tmp_path / "model.pkl"
    record = train_matchability(
        ["table", "facade"], [0], RunConfig(render=MEDIUM), renders_dir, out
    )
    assert set(record["held_out"]) == {"table", "facade"}
    held = record["held_out"]["table"]
    assert set(held["without"]) == {"scale", "contrast", "border", "repetition"}
    assert set(held["precision"]) == {"matchable", "octave-scale", "response"}
    assert json.loads(out.with_suffix(".json").read_text())["seeds"] == [0]
    models = read_models(str(out))
    assert set(models["models"]) == {"table", "facade", EVERY_TYPE}
    assert model_for(models, "templeSparseRing") is models["models"][EVERY_TYPE]
    assert model_for(models, "table") is models["models"]["table"]
    fe = front_end(
        medium_entry("table"), DetectorConfig(), SignalConfig(), renders_dir / "frontend"
    )
    cfg = MatchableConfig(matchability_model=str(out))
    for v, c, sig in zip(fe.views, fe.pools, fe.signals):
        inp = PolicyInput(v, c, sig, "table")
        idx = select("matchable", inp, 50, np.random.default_rng(0), cfg)
        assert len(idx) == len(set(idx.tolist())) == min(50, len(c))
        # each budget's selection is the view's one order, remembered between budgets
        order = predicted_order(model_for(models, "table"), features(inp))
        assert idx.tolist() == sorted(order[:50].tolist())
        assert select("matchable", inp, 20, None, cfg).tolist() == sorted(order[:20].tolist())


def test_a_memo_remembers_the_last_calls_and_recomputes_the_rest():
    calls = []

    @last_call(lambda x: (x,), size=2, hold=False)
    def square(x):
        calls.append(x)
        return x * x

    assert [square(x) for x in (2, 3, 2, 4, 3, 2)] == [4, 9, 4, 16, 9, 4]
    assert calls == [2, 3, 4, 3, 2]  # the least recently used goes: 4 puts 3 out, 3 puts 2 out


def test_the_shipped_model_never_saw_an_evaluation_seed_and_names_its_training():
    record = read_models("")
    assert set(record["models"]) == {*record["scenes"], EVERY_TYPE}
    assert not set(record["seeds"]) & set(BenchConfig().seeds)
    assert json.loads(SHIPPED_MODEL.with_suffix(".json").read_text())["held_out"]
    BenchConfig(scenes=("table",), methods=("matchable",)).validate()
    with pytest.raises(BenchError, match="matchability models were trained on seed"):
        BenchConfig(
            scenes=("table",), methods=("matchable",), seeds=(record["seeds"][0],)
        ).validate()


def test_an_unreadable_model_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.pkl"
    bad.write_bytes(b"not a pickle")
    with pytest.raises(BenchError, match="cannot read the matchability model"):
        read_models(str(bad))


def test_training_on_one_scene_type_is_refused_before_any_work(tmp_path):
    with pytest.raises(BenchError, match="two scene types or more"):
        train_matchability(["table"], [0], RunConfig(render=MEDIUM), tmp_path, tmp_path / "m.pkl")
    assert not list(tmp_path.iterdir())
