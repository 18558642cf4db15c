"""Candidate pools (`bench.frontend.pools`) and the pools of a grid (`bench.unit.pooled`):
every registered pool keeps the pool contract, a pool comes from a module of the user's
own, and one grid runs its methods on several pools, its rows named and paired."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from bench import ROOT, BenchError
from bench.frontend import plugins
from bench.frontend.features import DetectorConfig
from bench.frontend.pools import POOLS, PoolSpec
from bench.harness.execute import Cluster
from bench.harness.grid import BenchConfig, RunOptions, run_benchmark
from bench.results import Workspace
from bench.unit import pooled
from bench.unit.config import RunConfig
from bench.vocabulary import METHODS
from tests.conftest import TINY, blobs

BUILT_IN = ("sift", "orb", "akaze", "aliked", "disk", "xfeat")


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return blobs(1)


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_pool_keeps_the_pool_contract(texture, name):
    """Shapes and types, at most the configured count (exactly it where the image has
    more), the same pool twice, keypoints inside the image (COLMAP's convention)."""
    if POOLS[name].packages:
        pytest.importorskip("torch").set_num_threads(1)
    cfg = DetectorConfig(detector=name, max_features=60, learned_keypoints=60, learned_max_edge=160)
    first, again = (POOLS[name].detect(texture, cfg) for _ in range(2))
    xy, size, angle, response, desc = first
    n = len(xy)
    assert n == 60 and xy.shape == (n, 2) and xy.dtype == np.float64
    assert size.shape == angle.shape == response.shape == (n,) and len(desc) == n
    assert desc.dtype == (np.uint8 if POOLS[name].binary else np.float32)
    if not POOLS[name].binary:
        assert np.allclose(np.linalg.norm(desc, axis=1), 1, atol=1e-5)
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    assert xy.min() >= 0 and np.all(xy.max(0) <= [160, 120])
    points = POOLS[name].points(texture[..., 0], cfg)
    assert points.ndim == 2 and points.shape[1] == 2 and len(points) > 0


def test_a_pool_spec_names_a_pool_and_a_matcher_it_can_use():
    assert PoolSpec.parse("aliked") == ("aliked", "lightglue")
    assert PoolSpec.parse("aliked+ratio") == ("aliked", "ratio")
    assert str(PoolSpec("xfeat", "lighterglue")) == "xfeat"
    assert str(PoolSpec("xfeat", "ratio")) == "xfeat+ratio"
    for bad in ("sift+lightglue", "nopool", "aliked+lighterglue"):
        with pytest.raises(BenchError) as e:
            PoolSpec.parse(bad)
        assert "\n" not in str(e.value)


def test_placement_runs_pool_methods_on_each_pool_and_says_what_runs_on_none():
    own = PoolSpec("sift", "ratio")
    specs = (own, PoolSpec.parse("aliked"), PoolSpec.parse("aliked+ratio"))
    names, said = pooled.placement(("response", "colmap-b", "disk-b"), specs, own)
    assert names == (
        "response",
        "response:aliked",
        "response:aliked+ratio",
        "colmap-b",  # extracts its own: once
        "aliked-b",  # the pool's own top-B, with LightGlue, added
        "aliked-b:aliked+ratio",
    )
    assert METHODS["response:aliked+ratio"].pool == "aliked"
    assert METHODS["response:aliked+ratio"].matcher == "ratio"
    assert len(said) == 1 and "disk-b (its pool: disk) not on sift, aliked, aliked+ratio" in said[0]
    names, said = pooled.placement(("octave-scale", "disk-b"), specs[:2], own)
    assert names == ("octave-scale", "aliked-b")  # SIFT's octaves: on SIFT's pool alone
    assert "octave-scale (its pool: sift) not on aliked; disk-b" in said[0]
    for name in ("quadtree:aliked", "aliked-b:aliked+ratio"):  # as bench reproduce names them
        pooled.known(name)  # as the grid's check declares it
    names, said = pooled.placement(
        ("quadtree:aliked", "aliked-b:aliked+ratio", "quadtree"), specs, own
    )
    assert names == (
        "quadtree:aliked",  # on its own pool alone
        "aliked-b:aliked+ratio",
        "quadtree",
        "quadtree:aliked+ratio",
        "aliked-b",
    )
    assert "quadtree" not in said[0]  # a pooled name names its one pool itself


def test_a_pooled_name_is_declared_where_it_was_not(monkeypatch):
    """A worker process meets `<method>:<pool>` before anything declared it."""
    monkeypatch.setattr(pooled, "METHODS", {k: v for k, v in METHODS.items() if ":" not in k})
    monkeypatch.delitem(METHODS, "response:orb", raising=False)
    assert pooled.known("response:orb") == "response:orb"
    assert METHODS["response:orb"].pool == "orb"
    with pytest.raises(BenchError):
        pooled.known("response:nopool")
    with pytest.raises(BenchError):
        pooled.known("colmap-b:orb")  # extracts its own: on no pool


def test_a_pool_from_a_module_of_ones_own(tmp_path):
    """`--pool-module`: a pool registered by a file, with its origin recorded (its content
    decides its rows), usable in a grid; a file reading ground truth is refused."""
    module = tmp_path / "my_pool.py"
    module.write_text(
        textwrap.dedent(
            """
            import cv2
            import numpy as np
            from bench.frontend.pools import Pool, register_pool

            def detect(image, cfg):
                gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
                kps, desc = cv2.ORB_create(nfeatures=cfg.max_features).detectAndCompute(gray, None)
                xy = np.array([k.pt for k in kps], float).reshape(-1, 2) + 0.5
                n = len(xy)
                return xy, np.full(n, 8.0), np.full(n, -1.0), np.array([k.response for k in kps]), desc

            register_pool(Pool("my-orb", detect, lambda g, cfg: detect(g, cfg)[0], 0.2, binary=True))
            """
        )
    )
    plugins.load([str(module)])
    assert "my-orb" in POOLS and POOLS["my-orb"].identity()["pool module"]
    names, _ = pooled.placement(
        ("response",), (PoolSpec.parse("my-orb"),), PoolSpec("sift", "ratio")
    )
    assert names == ("response:my-orb",)
    bad = tmp_path / "bad_pool.py"
    bad.write_text("import numpy as np\nTRUTH = np.load('ground_truth/gt_00.npz')\n")
    with pytest.raises(BenchError, match="no ground truth"):
        plugins.load([str(bad)])


def test_one_grid_runs_a_method_on_two_pools_its_rows_named_and_paired(tmp_path, renders_dir):
    run = RunConfig(render=TINY)
    grid = BenchConfig(
        scenes=("table",),
        seeds=(0,),
        methods=("response",),
        budgets=(16,),  # ORB finds 29 keypoints in a tiny view
        tasks=("pairs",),
        pools=("sift", "orb"),
        run=run,
    )
    rows = run_benchmark(
        grid, Workspace(tmp_path / "r", renders_dir), RunOptions(cluster=Cluster(1))
    )
    by = rows.set_index("method")
    assert set(by.index) == {"response", "response:orb"}
    assert by.loc["response", "pool"] == "sift" and by.loc["response:orb", "pool"] == "orb"
    assert set(rows["matcher"]) == {"ratio"} and not rows["failure"].str.startswith("ERROR").any()
    assert by.loc["response", "prediction_hash"] != by.loc["response:orb", "prediction_hash"]
    assert rows.groupby(["scene", "seed", "budget", "bag"]).size().tolist() == [2]  # one cell
    again = run_benchmark(
        grid, Workspace(tmp_path / "r", renders_dir), RunOptions(cluster=Cluster(1))
    )
    assert len(again) == 2  # resumed: nothing computed twice


def test_table_pools_names_each_pools_peer_and_best_selection_against_colmap_b_and_its_top_b():
    """Hand-made rows on two pools: each pool's peer and best own-image selection, with its
    mean and its paired differences from `colmap-b` and from its pool's own top-B over the
    cells both have."""
    from bench.report.pools import recommendation, table_pools
    from bench.vocabulary import Vocabulary

    methods = {  # method: (pool, matcher, sfm mAA in each of 4 cells)
        "colmap-b": ("", "", [0.4, 0.5, 0.4, 0.5]),
        "octave-scale": ("sift", "ratio", [0.5, 0.5, 0.4, 0.6]),
        "scale": ("sift", "ratio", [0.3, 0.3, 0.3, 0.3]),
        "aliked-b": ("aliked", "lightglue", [0.9, 1.0, 0.8, 0.9]),
        "octave-scale:aliked": ("aliked", "lightglue", [0.8, 0.9, 0.9, 0.8]),
    }
    pooled.declare_pooled("octave-scale", PoolSpec.parse("aliked"))
    rows = [
        {"scene": sc, "seed": sd, "method": m, "budget": 256, "pool": p, "matcher": mt}
        | {"sfm_maa": v[2 * sc_i + sd]}
        for m, (p, mt, v) in methods.items()
        for sc_i, sc in enumerate(("facade", "table"))
        for sd in (0, 1)
    ]
    import pandas as pd

    frame = pd.DataFrame(rows)
    table = table_pools(frame.drop(columns=["pool", "matcher"]), Vocabulary.current(), frame)
    by = table.set_index(["pool", "role", "sees", "vs"])
    assert by.loc[("aliked/lightglue", "peer", "image", "colmap-b"), "method"] == "aliked-b"
    chosen = by.loc[("aliked/lightglue", "selection", "image")]
    assert set(chosen["method"]) == {"octave-scale:aliked"}
    assert chosen.loc["colmap-b", "mean_diff"] == pytest.approx(0.4)
    assert chosen.loc["aliked-b", "mean_diff"] == pytest.approx(-0.05)
    assert chosen.loc["aliked-b", "n"] == 4
    best = by.loc[("sift/ratio", "selection", "image", "colmap-b")]
    assert best["method"] == "octave-scale" and best["mean"] == pytest.approx(0.5)
    assert best["mean_diff"] == pytest.approx(0.05) and best["n"] == 4
    assert by.loc[("colmap", "peer", "image", ""), "method"] == "colmap-b"
    said = recommendation(table, Vocabulary.current())
    assert len(said) == 1 and said[0].startswith(
        "At B = 256 in sfm_maa, of the `image` selections `aliked-b` on the aliked/lightglue "
        "pool leads (0.900); against `colmap-b`: +0.450 ["
    )
    assert said[0].endswith("over 4 runs, tied.")  # 2 scenes: no interval
    one = frame.assign(pool="sift")
    assert table_pools(one, Vocabulary.current(), one).empty


def test_a_cross_pool_snapshots_grid_is_repeated_with_its_pools(tmp_path):
    """`bench reproduce` and `bench verdict` repeat a snapshot's grid: a cross-pool one's
    rows name their pools and matchers, and the run that repeats them must run on each."""
    import pandas as pd

    from bench.cli.common import snapshot_grid

    (tmp_path / "config.json").write_text('{"settings": {"render": null}}')
    rows = pd.DataFrame(
        {
            "method": ["colmap-b", "octave-scale", "aliked-b", "aliked-b:aliked+ratio"],
            "pool": ["", "sift", "aliked", "aliked"],
            "matcher": ["", "ratio", "lightglue", "ratio"],
            "protocol": ["none", "p", "p", "p"],
            "budget": [256] * 4,
            "task": ["sfm"] * 4,
        }
    )
    argv = snapshot_grid(tmp_path, rows)
    assert argv[argv.index("--pools") + 1] == "sift,aliked,aliked+ratio"
    assert "--pools" not in snapshot_grid(tmp_path, rows[rows["pool"] != "aliked"])
    assert "--pools" not in snapshot_grid(tmp_path, rows.drop(columns=["pool", "matcher"]))


@pytest.fixture
def forgets_declared_names():
    """Methods the test declares are forgotten after it: a method's own settings enter every
    `config.json` this process writes, which later tests compare with their own."""
    from bench.frontend.policies import MULTIVIEW, POLICIES

    registries = (METHODS, pooled.SETTINGS, POLICIES, MULTIVIEW, plugins.ORIGIN)
    before = [set(r) for r in registries]
    yield
    for registry, names in zip(registries, before):
        for name in set(registry) - names:
            del registry[name]


def test_a_cross_pool_snapshots_settings_are_read_with_its_pooled_methods_own_settings(
    forgets_declared_names,
):
    """A grid on pools records `track-first:aliked`'s own settings; reading them back (a
    snapshot's origin, `bench verdict`) declared no pooled name and refused the folder, so
    `bench publish` recorded no origin."""
    from bench.binding import read_settings
    from bench.cli.common import settings_config

    settings = read_settings(ROOT / "results" / "published-pools")
    assert "track-first:aliked" in settings["methods"]
    cfg = settings_config(settings)
    assert cfg.policy_config("track-first:aliked") == cfg.policy_config("track-first")


def test_a_peer_whose_pool_is_not_installed_is_not_paired_and_says_why(
    monkeypatch, forgets_declared_names
):
    """`bench verdict examples/my_pool.py` on a clone without the `learned` extra stopped
    on the cross-pool snapshot's `aliked-b` rows (their protocol names ALIKED's package
    versions); they are left unpaired with one line, and the verdict goes on."""
    from dataclasses import replace

    from bench.binding import read_settings
    from bench.cli.common import settings_config
    from bench.frontend.pools import POOLS
    from bench.harness.origin import protocol_changes, read_origin

    snapshot = ROOT / "results" / "published-pools"
    monkeypatch.setitem(POOLS, "aliked", replace(POOLS["aliked"], packages=("no-such-package",)))
    cfg = settings_config(read_settings(snapshot))
    said = protocol_changes(read_origin(snapshot), cfg, [("aliked-b", "sfm"), ("colmap-b", "sfm")])
    assert "the aliked pool needs the `learned` extra" in said["aliked-b", "sfm"]
