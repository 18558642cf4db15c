"""`colmap-tracks-b`: stock COLMAP's peer of the selections that see other views (issue 53):
B keypoints per view, those of the longest verified tracks of a 4B first pass."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.backend.matching import BackendConfig
from bench.backend.peers import CAPS, TRACKS, longest_tracks, peer_extraction, run_peer
from bench.cli import main
from bench.evaluation.export import export_dataset
from bench.frontend.tracks import TrackFirstConfig
from bench.frontend.views import load_views
from bench.harness.grid import BenchConfig, default_methods
from bench.unit.methods import runner
from bench.vocabulary import NO_PROTOCOL, TRACKS_FIRST_PASS, VIEWS, Job, Vocabulary
from tests.test_policies import _dataset

PEER = "colmap-tracks-b"
BUDGET = 48


def _run(folder, budget=BUDGET, peer=PEER, protocols=()):
    views = load_views(folder)
    names, cams = [v.name for v in views], [v.camera for v in views]
    images = folder / "images" if (folder / "images").is_dir() else folder
    extracted = peer_extraction(images, names, cams, peer, budget)
    keep = budget if CAPS[peer] == TRACKS else 0
    return run_peer(names, cams, extracted, BackendConfig(), list(protocols), keep)


def test_its_first_pass_is_track_firsts():
    assert TRACKS_FIRST_PASS == TrackFirstConfig().first_pass


def test_the_longest_tracks_are_kept_ties_in_colmaps_order():
    spans = np.array([0, 3, 2, 3, 0, 5, 2])
    assert longest_tracks(spans, 3).tolist() == [1, 3, 5]
    assert longest_tracks(spans, 4).tolist() == [1, 2, 3, 5]  # 2 before 6: COLMAP's order
    assert longest_tracks(spans, 10).tolist() == list(range(7))


@pytest.fixture(scope="module")
def rig(medium_entry, tmp_path_factory):
    """The table's images and rig as a dataset folder, and the same with random poses."""
    entry, out = medium_entry("table"), tmp_path_factory.mktemp("tracks-peer")
    return _dataset(entry, out / "true"), _dataset(entry, out / "random", np.random.default_rng(0))


def test_it_keeps_exactly_b_per_view_of_a_4b_first_pass_and_sees_no_poses(rig):
    """B in every view (COLMAP finds more than 4B here), of COLMAP's own extraction, other
    than colmap-b's B, and array-equal with the rig's poses replaced by
    random ones: it reads the images and the intrinsics alone."""
    true, wrong = rig
    ours, whole = _run(true, protocols=["multiview"]), _run(true, 0, "colmap")
    assert [len(k) for k in ours.keypoints] == [BUDGET] * len(whole.keypoints)
    assert all(len(k) > 4 * BUDGET for k in whole.keypoints)
    for kept, every in zip(ours.keypoints, whole.keypoints):  # of COLMAP's own extraction
        assert {tuple(p) for p in kept} <= {tuple(p) for p in every}
    capped = _run(true, peer="colmap-b")
    assert any(not np.array_equal(a, b) for a, b in zip(ours.keypoints, capped.keypoints))
    assert ours.seconds["select"] > 0 and ours.recs["multiview"].model is not None
    blind = _run(wrong)
    assert all(np.array_equal(a, b) for a, b in zip(ours.keypoints, blind.keypoints))


def test_it_is_in_the_default_grid_for_sfm_and_pairs_at_every_budget():
    grid = BenchConfig(tasks=("tri", "sfm", "pairs"))
    assert PEER in default_methods() and Vocabulary.current().sees(PEER) == VIEWS
    assert grid.jobs(PEER) == [*(Job("sfm", p) for p in grid.protocols), Job("pairs", NO_PROTOCOL)]
    budgets = {u.budget for u in grid.units() if u.method == PEER}
    assert budgets == set(grid.budgets) == {128, 256, 512}
    assert runner(PEER).read is not None and not runner(PEER).photos


def test_it_runs_on_a_dataset_in_bags(medium_entry, renders_dir, tmp_path):
    dataset = export_dataset(medium_entry("table"), tmp_path / "table-ds")
    out = tmp_path / "r"
    argv = ["run", "--dataset", str(dataset), "--methods", f"texture,colmap-b,{PEER}"]
    argv += ["--budget", str(BUDGET), "--tasks", "sfm,pairs", "--protocols", "multiview"]
    argv += ["--workers", "1", "--renders", str(renders_dir), "--results", str(out)]
    assert main([*argv, "--bag-size", "4", "--bags", "1"]) == 0
    rows = pd.read_csv(out / "runs.csv").set_index(["method", "task"])
    assert rows.loc[(PEER, "pairs"), "status"] == "ok" and (rows.loc[PEER, "views"] == 4).all()
    assert not rows.loc[PEER, "failure"].fillna("").str.startswith("error").any()
    assert (rows.loc[PEER, "keypoints_per_view"] == BUDGET).all()
    assert pd.read_csv(out / "table1.csv").set_index("method").loc[PEER, "sees"] == VIEWS
