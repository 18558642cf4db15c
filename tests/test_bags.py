"""Bags: random co-visible subsets of a dataset's images, each scored as a scene of its own
(`bench.unit.bags`)."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
import pytest
from scipy.sparse.csgraph import connected_components

from bench.cli import main
from bench.evaluation.export import export_dataset
from bench.evaluation.relative import MIN_SHARED
from bench.runs import read_runs
from bench.unit.bags import draw_bags
from bench.vocabulary import BAG


def test_bags_on_a_chain_are_its_runs_of_consecutive_views_each_once():
    chain = {(0, 1), (1, 2), (2, 3), (3, 4)}
    bags = draw_bags(5, chain, 3, 10)
    assert sorted(bags) == [(0, 1, 2), (1, 2, 3), (2, 3, 4)]  # every connected 3 of 5, once
    assert draw_bags(5, chain, 3, 10) == bags  # seeded


def test_a_bag_as_large_as_the_set_is_the_set_and_unreachable_sizes_give_none():
    assert draw_bags(4, {(0, 1)}, 4, 10) == [(0, 1, 2, 3)]
    assert draw_bags(4, {(0, 1)}, 0, 10) == [(0, 1, 2, 3)]
    assert draw_bags(4, {(0, 1), (2, 3)}, 3, 10) == []


def test_every_bag_is_connected_and_distinct_on_a_random_graph():
    rng = np.random.default_rng(3)
    links = {p for p in combinations(range(12), 2) if rng.random() < 0.25}
    bags = draw_bags(12, links, 5, 20)
    assert len(bags) == 20 and len(set(bags)) == 20
    for bag in bags:
        adj = np.array([[(a, b) in links or (b, a) in links for b in bag] for a in bag])
        assert len(bag) == 5 and connected_components(adj, directed=False)[0] == 1


@pytest.fixture(scope="module")
def dataset(medium_entry, tmp_path_factory):
    return export_dataset(medium_entry("table"), tmp_path_factory.mktemp("bags") / "table-ds")


def test_a_dataset_run_scores_each_bag_on_its_own_views_and_reuses_them(
    dataset, renders_dir, tmp_path, capsys
):
    out = tmp_path / "r"
    argv = ["run", "--dataset", str(dataset), "--methods", "texture", "--budget", "64"]
    argv += ["--tasks", "pairs", "--protocols", "multiview", "--workers", "1"]
    argv += ["--renders", str(renders_dir), "--results", str(out)]
    assert main([*argv, "--bag-size", "4", "--bags", "2"]) == 0
    rows = pd.read_csv(out / "runs.csv")
    assert sorted(rows["seed"]) == [0, 1] and (rows["views"] == 4).all()
    bags = [b.split() for b in rows[BAG]]
    assert all(len(b) == 4 for b in bags) and bags[0] != bags[1]
    assert (rows["pairs_scored"] <= 6).all()  # the pairs of 4 views, not of the set's 6
    capsys.readouterr()
    assert main([*argv, "--bag-size", "4", "--bags", "2"]) == 0
    assert "2 of 2 rows already" in capsys.readouterr().err
    assert main([*argv, "--bag-size", "0"]) == 0  # other bags: other rows, beside them
    assert "2 of 3 rows already" in capsys.readouterr().err
    after = read_runs(out / "runs.csv")
    assert len(after) == 3 and set(after[BAG]) == {*rows[BAG], ""}
    # the page reads the bags it asked for alone: one unit, not the three of the folder
    assert pd.read_csv(out / "table_scenes.csv")["seeds"].tolist() == [1]
    assert pd.read_csv(out / "table1.csv")["runs"].tolist() == [1]
    whole = after[after[BAG] == ""]  # no bag: the whole set
    assert len(whole) == 1 and whole["views"].iloc[0] == 6 and whole["seed"].iloc[0] == 0
    # the folder alone cannot say which bags a page is of: one line, and the rows kept
    assert main(["plot", "--results", str(out), "--renders", str(renders_dir)]) == 2
    assert "has rows of bags of 4 and 6 views: a page is of one bag size" in (
        capsys.readouterr().err
    )
    assert len(read_runs(out / "runs.csv")) == 3


def test_a_bags_signals_are_those_of_its_views_alone(dataset, tmp_path):
    from bench.frontend.geometry import IMAGES
    from bench.frontend.signals import SIGNALS, compute_signals
    from bench.frontend.stage import front_end, subset
    from bench.unit.config import RunConfig

    cfg, bag = RunConfig(), (0, 2, 3, 5)
    full = front_end(dataset, cfg.detector, cfg.signals, tmp_path, IMAGES)
    mine = subset(full, bag, cfg.detector, cfg.signals)
    alone, _ = compute_signals([full.views[i] for i in bag], mine.pools, cfg.detector, cfg.signals)
    assert [v.name for v in mine.views] == [full.views[i].name for i in bag]
    for got, want in zip(mine.signals, alone):
        for s in SIGNALS:
            np.testing.assert_allclose(getattr(got, s), getattr(want, s), atol=1e-9, err_msg=s)
    # the views' other neighbours are gone: some cross-view signal differs from the set's
    assert any(
        not np.allclose(getattr(mine.signals[k], s), getattr(full.signals[i], s))
        for k, i in enumerate(bag)
        for s in ("ambiguity", "parallax", "epipolar")
    )


def test_a_bagged_whole_set_front_end_gives_every_bag_the_same_front_end(dataset, tmp_path):
    from bench.frontend.geometry import IMAGES
    from bench.frontend.stage import front_end, subset
    from bench.unit.config import RunConfig

    cfg, bag = RunConfig(), (1, 2, 4, 5)
    full = front_end(dataset, cfg.detector, cfg.signals, tmp_path, IMAGES)
    alone = front_end(dataset, cfg.detector, cfg.signals, tmp_path, IMAGES, bagged=True)
    assert len(list(tmp_path.glob("*.npz"))) == 2  # cached apart: neither is the other
    assert not alone.seconds["geometry"] and alone.seconds["detect"] > 0
    assert not any(g.parallax.any() or g.ambiguity.any() for g in alone.signals)
    want, got = (
        subset(full, bag, cfg.detector, cfg.signals),
        subset(alone, bag, cfg.detector, cfg.signals),
    )
    _assert_same_front_end(want, got)


def _assert_same_front_end(want, got):
    """The same candidates and signals, to the last bit."""
    from bench.frontend.signals import SIGNALS

    for a, b in zip(want.pools, got.pools, strict=True):
        np.testing.assert_array_equal(a.xy, b.xy)
        np.testing.assert_array_equal(a.descriptors, b.descriptors)
    for a, b in zip(want.signals, got.signals, strict=True):
        for s in SIGNALS:
            np.testing.assert_array_equal(getattr(a, s), getattr(b, s), err_msg=s)


def test_bag_options_default_apply_to_datasets_alone_and_not_to_the_next_views_task(capsys):
    from argparse import Namespace

    from bench import BenchError
    from bench.cli.run import bags_arg

    none = Namespace(bag_size=None, bags=None)
    assert bags_arg(none, True, ("sfm", "pairs")) == (6, 10)
    assert bags_arg(Namespace(bag_size=0, bags=7), True, ("sfm",)) == (0, 1)
    assert bags_arg(Namespace(bag_size=4, bags=3), True, ("nbv",)) == (0, 1)
    assert "--bag-size and --bags ignored with --tasks nbv" in capsys.readouterr().err
    bags_arg(Namespace(bag_size=4, bags=None), False, ("sfm",))
    assert "--bag-size ignored without --dataset" in capsys.readouterr().err
    bags_arg(Namespace(bag_size=None, bags=3), False, ("sfm",))
    assert "--bags ignored without --dataset: rendered scenes have their rigs" in (
        capsys.readouterr().err
    )
    with pytest.raises(BenchError, match="--bags must be at least 1"):
        bags_arg(Namespace(bag_size=4, bags=0), True, ("sfm",))


def test_two_views_are_co_visible_from_exactly_min_shared_common_points():
    """Views 0 and 1 share `MIN_SHARED` model points; view 2 shares one fewer with each."""
    seen = [np.arange(MIN_SHARED), np.arange(MIN_SHARED), np.arange(1, MIN_SHARED)]
    from bench.evaluation.truth import covisible_pairs

    assert covisible_pairs([None] * 3, seen, MIN_SHARED)[0] == [(0, 1)]


@pytest.mark.parametrize("turn_deg", [0.0, 2.0])
def test_a_forward_sequence_without_points_is_covisible_near_only_and_bagged_in_runs(turn_deg):
    """Driving forward (KITTI's motion), a model with poses and no points: the optical axes
    lie along the path, so the point where they pass closest is behind the cameras or
    undefined (the test said no pair, turning, or every pair, straight); now a view sees
    the scene at the working distance of its neighbours (5.7 m at 1 m a frame) within a
    factor 2 of scale, so the views at most 5 frames apart, and a bag is a run of nearby
    frames, not frames from the whole sequence."""
    from bench.camera import look_at
    from bench.evaluation.truth import covisible_pairs

    yaw = np.radians(turn_deg * np.arange(30))  # 1 m a frame, turning by turn_deg a frame
    heading = np.c_[np.sin(yaw), np.cos(yaw), np.zeros(30)]
    eyes = np.cumsum(heading, axis=0) - heading
    cams = [
        look_at(e, e + 10 * h, width=1241, height=376, fov_x_deg=82) for e, h in zip(eyes, heading)
    ]
    pairs, _ = covisible_pairs(cams, None, 15)
    assert pairs == [(i, j) for i, j in combinations(range(30), 2) if j - i <= 5]
    for bag in draw_bags(30, pairs, 6, 10):
        assert bag[-1] - bag[0] <= 25 and max(np.diff(bag)) <= 5


def test_forward_covisibility_tests_the_scale_change_both_ways():
    """Two views on one forward line, the second 15/16 of the working distance ahead:
    the point at that distance on the first's axis is 16 times nearer the second (beyond
    one octave), and the second's point falls outside the first's narrow image. Only a
    two-sided scale test says they are not covisible; on a straight path the other
    direction always covers a one-sided test, so here the intrinsics differ."""
    from bench.camera import Camera
    from bench.evaluation.truth import SCALE_CHANGE, _facing

    depth = 10.0

    def cam(centre, f):
        return Camera(640, 480, f, f, 320.0, 240.0, np.eye(3), -np.asarray(centre, float))

    narrow, wide = cam([0, 0, 0], 12400.0), cam([0.5, 0, depth * 15 / 16], 200.0)
    assert depth / (depth - wide.center[2]) > SCALE_CHANGE  # 16: beyond one octave
    assert not _facing(narrow, wide, depth) and not _facing(wide, narrow, depth)
    near = cam([0.5, 0, depth / 4], 200.0)  # 4/3 nearer: within an octave
    assert _facing(narrow, near, depth)


def test_a_bags_front_end_is_computed_once_and_read_back_as_computed(
    dataset, tmp_path, monkeypatch
):
    from bench.frontend import stage
    from bench.frontend.geometry import IMAGES
    from bench.unit.config import RunConfig

    cfg, bag = RunConfig(), (0, 3, 4)
    det, sig = cfg.detector, cfg.signals
    alone = stage.front_end(dataset, det, sig, tmp_path, IMAGES, bagged=True)
    first = stage.bag_front_end(dataset, det, sig, tmp_path, IMAGES, alone, bag)
    want = stage.subset(alone, bag, det, sig)
    other = stage.bag_front_end(dataset, det, sig, tmp_path, IMAGES, alone, (0, 3, 5))
    assert len(list(tmp_path.glob("*-bag-*.npz"))) == 2 and not other.cached
    monkeypatch.setattr(stage, "subset", lambda *a: pytest.fail("the bag computed again"))
    again = stage.bag_front_end(dataset, det, sig, tmp_path, IMAGES, alone, bag)
    assert again.cached and not first.cached
    assert [v.name for v in again.views] == [alone.views[i].name for i in bag]
    assert again.seconds == first.seconds
    _assert_same_front_end(want, again)
