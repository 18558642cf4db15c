"""Equal keypoints (`<policy>@<peer>`): the peer's own count in every view, and its table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.backend.equal_count import EQUAL, peer_counts
from bench.backend.matching import BackendConfig, matcher
from bench.backend.peers import peer_extraction, run_peer
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import IMAGES, SignalConfig
from bench.frontend.policies import PolicyConfig, PolicyInput, settings_for
from bench.frontend.selection import select_views
from bench.frontend.stage import front_end
from bench.frontend.views import Source
from bench.harness.grid import BenchConfig
from bench.report.page import _equal_section
from bench.report.tables import equal_keypoints, headline_frame
from bench.results import PREDICTION, TABLE1_EQUAL, Workspace
from bench.unit.config import RunConfig
from bench.vocabulary import EQUAL_COUNT, METHODS, Unit, Vocabulary, equal_parts
from tests.conftest import MEDIUM, bench_run

BUDGET = 64


@pytest.fixture(scope="module")
def fe(medium_entry, frontend_cache):
    entry = medium_entry("table")
    return entry, front_end(entry, DetectorConfig(), SignalConfig(), frontend_cache, IMAGES)


def test_the_count_is_the_peers_own_in_every_view(fe):
    """The soft limit holds whole scale levels: counts other than B, equal to the peer's."""
    entry, front = fe
    names, cams = [v.name for v in front.views], [v.camera for v in front.views]
    images = Source.of(entry).images
    counts = peer_counts(images, names, cams, "colmap-soft-b", BUDGET)
    soft = peer_extraction(images, names, cams, "colmap-soft-b", BUDGET)
    run = run_peer(names, cams, soft, BackendConfig(), [])
    assert counts == [len(k) for k in run.keypoints]
    assert any(c != BUDGET for c in counts)
    hard = peer_counts(images, names, cams, "colmap-b", BUDGET)
    every = peer_extraction(images, names, cams, "colmap", 0)
    assert hard == [
        min(BUDGET, len(k)) for k in run_peer(names, cams, every, BackendConfig(), []).keypoints
    ]


@pytest.mark.parametrize("method", ["cross-view@colmap-soft-b", "track-first@colmap-soft-b"])
def test_the_selection_holds_the_count_of_each_view_at_most_the_pool(fe, method):
    _, front = fe
    inputs = [PolicyInput(v, c, s) for v, c, s in zip(front.views, front.pools, front.signals)]
    pools = [len(c) for c in front.pools]
    counts = [0, 1, 17, 100, pools[4] + 5, 64][: len(inputs)]
    cams = [v.camera for v in front.views]
    match = matcher(cams, front.pools, BackendConfig(), "sift")
    own = settings_for(method, PolicyConfig())
    sel, rounds = select_views(EQUAL[method][0], inputs, counts, 0, own, match)
    assert rounds == []
    assert [len(s) for s in sel] == [min(c, n) for c, n in zip(counts, pools)]
    assert all(len(np.unique(s)) == len(s) for s in sel)


def test_a_unit_selects_exactly_the_peers_count_per_view(medium_entry, tmp_path):
    """End to end: the stored selection of `cross-view@colmap-soft-b` holds, in each view,
    as many keypoints as the stored prediction of `colmap-soft-b` at the same budget."""
    medium_entry("table")
    renders = medium_entry("table").parent
    grid = BenchConfig(
        scenes=("table",),
        seeds=(0,),
        methods=("texture", "colmap-soft-b", "cross-view@colmap-soft-b"),  # table2 needs a baseline
        budgets=(BUDGET,),
        tasks=("pairs",),
        protocols=("multiview",),
        run=RunConfig(render=MEDIUM),
    )
    bench_run(grid, tmp_path, renders)
    ws = Workspace(tmp_path, renders)
    peer = ws.unit_dir(Unit("table", 0, "colmap-soft-b", BUDGET)) / f"{PREDICTION}-peer.npz"
    ours = ws.unit_dir(Unit("table", 0, "cross-view@colmap-soft-b", BUDGET))
    with np.load(peer) as p, np.load(ours / f"{PREDICTION}-{IMAGES}.npz") as s:
        views = len([k for k in p.files if k.startswith("keypoints_")])
        want = [len(p[f"keypoints_{v}"]) for v in range(views)]
        got = [len(s[f"selection_{v}"]) for v in range(views)]
    assert got == want and any(n != BUDGET for n in want)
    rows = pd.read_csv(tmp_path / "runs.csv").set_index("method")
    kpv = rows["keypoints_per_view"]
    assert kpv["cross-view@colmap-soft-b"] == pytest.approx(np.mean(want))
    assert kpv["cross-view@colmap-soft-b"] == pytest.approx(kpv["colmap-soft-b"])
    assert (tmp_path / TABLE1_EQUAL).is_file()


def test_every_equal_method_is_a_declared_per_view_policy_at_a_peer():
    assert EQUAL
    for name, (policy, peer) in EQUAL.items():
        assert equal_parts(name) == (policy, peer)
        assert METHODS[name].kind == EQUAL_COUNT and METHODS[peer].role == "peer"
        assert METHODS[name].reads == METHODS[policy].reads


def test_the_equal_table_pairs_each_method_with_its_peer_by_hand():
    """Two seeds: cross-view@colmap-soft-b 0.5 and 0.9 against 0.2 and 0.4: +0.4 mean, 2/0/0;
    keypoints per view as each ran; colmap-b is no equal-count method's peer."""
    rows = []
    for seed, (ours, theirs) in enumerate(((0.5, 0.2), (0.9, 0.4))):
        cell = dict(scene="s", seed=seed, budget=256, task="sfm", protocol="multiview")
        cell |= dict(status="ok", views=6, registered_views=6)
        rows.append(
            cell | dict(method="cross-view@colmap-soft-b", maa=ours, keypoints_per_view=110)
        )
        rows.append(cell | dict(method="colmap-soft-b", maa=theirs, keypoints_per_view=110))
        rows.append(cell | dict(method="colmap-b", maa=0.0, keypoints_per_view=64))
    vocab = Vocabulary.current()
    t = equal_keypoints(headline_frame(pd.DataFrame(rows), vocab), vocab)
    pooled = t[(t["scene"] == "all scenes") & (t["metric"] == "sfm_maa")]
    assert len(pooled) == 1 and set(t["peer"]) == {"colmap-soft-b"}
    r = pooled.iloc[0]
    assert (r["method"], r["peer"], r["n"]) == ("cross-view@colmap-soft-b", "colmap-soft-b", 2)
    assert r["mean_diff"] == pytest.approx(0.4) and (r["wins"], r["losses"]) == (2, 0)
    assert r["method_kpv"] == r["peer_kpv"] == 110
    page = "\n".join(_equal_section(t))
    assert "sfm_maa at 256" in page and "`cross-view@colmap-soft-b` +0.40 [" in page
