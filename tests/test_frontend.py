"""The candidate pool, the signals and the per-view policies (plus `all`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from bench import BenchError
from bench.camera import look_at, write_colmap_rig
from bench.cli import main
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.geometry import IMAGES, RIG, epipolar_distances, parallax
from bench.frontend.policies import (
    POLICIES,
    PolicyConfig,
    PolicyInput,
    Weights,
    select,
    tile_of,
)
from bench.frontend.signals import (
    SIGNALS,
    SignalConfig,
    Signals,
    compute_signals,
)
from bench.frontend.stage import cache_file, front_end
from bench.frontend.views import View, load_image_folder
from tests.test_select import photos

BUDGET = 64


@pytest.fixture(scope="module")
def table_front(tiny_entry, tmp_path_factory):
    from bench.render.entry import render_scene
    from tests.conftest import TINY

    entry = render_scene(
        "table",
        0,
        type(TINY)(width=320, height=240, spp=4, max_depth=2),
        tiny_entry("table").parent,
    )
    fe = front_end(entry, DetectorConfig(), SignalConfig(), tmp_path_factory.mktemp("fe"))
    fe.entry = entry
    return fe


def _inputs(fe):
    return [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]


def test_pool_is_several_times_the_budget_and_in_colmap_convention(table_front):
    for view, cand in zip(table_front.views, table_front.pools):
        assert len(cand) > 3 * BUDGET
        kps = cv2.SIFT_create(contrastThreshold=DetectorConfig().sift_contrast).detect(
            view.gray, None
        )
        np.testing.assert_allclose(
            np.sort(cand.xy[:, 0])[:5], np.sort([k.pt[0] + 0.5 for k in kps])[:5]
        )
        assert cand.descriptors.shape == (len(cand), 128)


@pytest.mark.parametrize("detector", ["orb", "akaze"])
def test_other_detectors_give_a_pool(table_front, detector):
    cand = detect(table_front.views[0], DetectorConfig(detector=detector))
    assert len(cand) > BUDGET and cand.descriptors.dtype == np.uint8


def test_signals_are_in_unit_interval(table_front):
    for cand, sig in zip(table_front.pools, table_front.signals):
        for name in SIGNALS:
            x = getattr(sig, name)
            assert x.shape == (len(cand),) and np.all((x >= 0) & (x <= 1)), name
            if name not in ("parallax", "epipolar"):  # the table arc: ample parallax
                assert x.max() > x.min(), f"{name} does not discriminate"


def test_front_end_cache_hit_gives_identical_arrays(table_front, tmp_path):
    first = front_end(table_front.entry, DetectorConfig(), SignalConfig(), tmp_path)
    again = front_end(table_front.entry, DetectorConfig(), SignalConfig(), tmp_path)
    assert not first.cached and again.cached and again.seconds == first.seconds
    for a, b in zip(first.signals, again.signals):
        assert all(np.array_equal(getattr(a, s), getattr(b, s)) for s in SIGNALS)
    assert np.array_equal(first.pools[2].descriptors, again.pools[2].descriptors)


def test_a_front_end_of_large_views_shows_its_progress(table_front, tmp_path, monkeypatch, capsys):
    """A step per view detected and per view's signals, shown where the views are large
    (`PROGRESS_PIXELS`; a render's are not), with the same arrays as without."""
    from bench.frontend import stage

    quiet = front_end(table_front.entry, DetectorConfig(), SignalConfig(), tmp_path / "a")
    assert "features:" not in capsys.readouterr().err
    monkeypatch.setattr(stage, "PROGRESS_PIXELS", 1)
    shown = front_end(table_front.entry, DetectorConfig(), SignalConfig(), tmp_path / "b")
    views = len(shown.views)
    assert f"features: {2 * views}/{2 * views} step (100 %)" in capsys.readouterr().err
    for a, b in zip(quiet.signals, shown.signals):
        assert all(np.array_equal(getattr(a, s), getattr(b, s)) for s in SIGNALS)


@pytest.mark.parametrize("name", list(POLICIES))
def test_exact_budget_distinct_indices(table_front, name):
    for inp in _inputs(table_front):
        idx = select(name, inp, BUDGET, np.random.default_rng(0))
        want = len(inp.candidates) if name == "all" else BUDGET
        assert len(idx) == want == len(set(idx.tolist()))
        small = select(name, inp, 10**6, np.random.default_rng(0))
        assert len(small) == len(inp.candidates)  # budget above the pool: the whole pool


@pytest.mark.parametrize("name", list(POLICIES))
def test_deterministic_per_seed(table_front, name):
    inp = _inputs(table_front)[1]
    a, b = (select(name, inp, BUDGET, np.random.default_rng(7)) for _ in range(2))
    assert np.array_equal(a, b)
    if name == "random":
        assert not np.array_equal(
            np.sort(a), np.sort(select(name, inp, BUDGET, np.random.default_rng(8)))
        )


def test_grid_fills_every_tile_that_has_a_candidate(table_front):
    cfg = PolicyConfig()
    for inp in _inputs(table_front):
        cam = inp.view.camera
        tiles = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
        idx = select("grid", inp, BUDGET, np.random.default_rng(0), cfg)
        assert set(tiles[idx]) == set(tiles)


def test_adaptive_never_exceeds_its_tile_cap(table_front):
    cfg = PolicyConfig()
    for inp in _inputs(table_front):
        cam = inp.view.camera
        tiles = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
        idx = select("adaptive", inp, BUDGET, np.random.default_rng(0), cfg)
        cap = int(np.ceil(cfg.cap_factor * BUDGET / len(np.unique(tiles))))
        assert np.bincount(tiles[idx]).max() <= cap
        # texture-only, for contrast, does concentrate somewhere beyond that cap
    texture = select("texture", _inputs(table_front)[0], BUDGET, np.random.default_rng(0))
    tiles0 = tile_of(table_front.pools[0].xy, 320, 240, cfg.tiles)
    assert np.bincount(tiles0[texture]).max() > int(
        np.ceil(cfg.cap_factor * BUDGET / len(np.unique(tiles0)))
    )


def _motif_image() -> tuple[np.ndarray, np.ndarray]:
    """A noisy image with one motif repeated eight times and eight unique motifs."""
    rng = np.random.default_rng(0)
    img = (rng.normal(128, 3, (240, 480))).clip(0, 255).astype(np.uint8)
    motif = (rng.random((24, 24)) * 255).astype(np.uint8)
    centres = []
    for k in range(16):
        x, y = 40 + (k % 8) * 55, 60 if k < 8 else 180
        patch = motif if k < 8 else (rng.random((24, 24)) * 255).astype(np.uint8)
        img[y - 12 : y + 12, x - 12 : x + 12] = cv2.resize(
            patch, (24, 24), interpolation=cv2.INTER_NEAREST
        )
        centres.append((x, y))
    return cv2.GaussianBlur(img, (0, 0), 0.8), np.array(centres, float)


def test_repeated_motif_is_ambiguous_unique_motif_is_distinctive():
    img, centres = _motif_image()
    cam = look_at((0, -7, 0), (0, 0, 0), width=480, height=240)
    view = View(0, "motif.png", np.repeat(img[..., None], 3, 2), cam, posed=False)
    cand = detect(view, DetectorConfig(sift_contrast=0.02))
    d, owner = (
        np.linalg.norm(cand.xy[:, None] - centres[None] - 0.5, axis=2).min(1),
        np.linalg.norm(cand.xy[:, None] - centres[None] - 0.5, axis=2).argmin(1),
    )
    near = d < 14
    repeated, unique = near & (owner < 8), near & (owner >= 8)
    assert repeated.sum() >= 8 and unique.sum() >= 8
    det = DetectorConfig(sift_contrast=0.02)
    (sig,), _ = compute_signals([view], [cand], det, SignalConfig())
    a, q = sig.ambiguity, sig.distinctiveness
    assert not sig.parallax.any() and not sig.epipolar.any()  # one view: nothing overlaps
    assert a[repeated].mean() > a[unique].mean() + 0.2
    assert q[repeated].mean() < q[unique].mean() - 0.2
    n = len(cand)
    flat = np.full(n, 0.5)
    sig = Signals(**{name: flat for name in SIGNALS} | {"distinctiveness": q, "ambiguity": a})
    k = int(unique.sum())
    idx = select(
        "adaptive",
        PolicyInput(view, cand, sig),
        k,
        np.random.default_rng(0),
        PolicyConfig(tiles=(1, 1)),
    )
    assert unique[idx].mean() > 0.75


def test_parallax_is_low_near_the_epipole():
    # two cameras, the second 1 unit straight ahead: the epipole is the image centre
    a = look_at((0, 0, 0), (0, 10, 0), width=400, height=300)
    b = look_at((0, 1, 0), (0, 11, 0), width=400, height=300)
    xy = np.array([[200.5, 150.5], [210.5, 150.5], [260.5, 150.5], [330.5, 150.5]])
    from bench.frontend.features import Candidates

    cand = Candidates(xy, np.ones(4), np.zeros(4), np.ones(4), np.zeros((4, 128), np.float32))
    p = parallax(cand, [a, b], 0, 7.0)
    assert p[0] < 0.02 and np.all(np.diff(p) > 0)


def test_bad_policy_input_is_a_clear_error(table_front):
    inp = _inputs(table_front)[0]
    with pytest.raises(
        BenchError, match="unknown method 'best'; valid: random, texture, grid, adaptive, "
    ):
        select("best", inp, BUDGET, np.random.default_rng(0))
    with pytest.raises(BenchError, match="budget must be positive"):
        select("random", inp, 0, np.random.default_rng(0))
    with pytest.raises(BenchError, match="weights must be five numbers"):
        PolicyConfig(weights=Weights(texture="x")).validate()
    with pytest.raises(BenchError, match="unknown detector 'surf'; valid: sift, orb, akaze"):
        DetectorConfig(detector="surf").validate()


def test_policy_input_has_no_ground_truth_fields():
    import dataclasses

    from bench.frontend.features import Candidates

    assert [f.name for f in dataclasses.fields(PolicyInput)] == [
        "view",
        "candidates",
        "signals",
        "scene",
    ]
    assert [f.name for f in dataclasses.fields(View)] == [
        "index",
        "name",
        "pixels",
        "camera",
        "posed",
        "focal_known",
    ]
    assert [f.name for f in dataclasses.fields(Candidates)] == [
        "xy",
        "size",
        "angle",
        "response",
        "descriptors",
    ]


def test_only_the_wanted_costly_signals_are_computed(table_front):
    wanted = ("texture", "repeatability", "distinctiveness", "ambiguity", "parallax")
    views, pools = table_front.views, table_front.pools
    sigs, seconds = compute_signals(views, pools, DetectorConfig(), SignalConfig(), wanted)
    assert seconds["repeatability_redetect"] == seconds["epipolar"] == 0
    for part, full in zip(sigs, table_front.signals):
        assert not part.repeatability_redetect.any() and not part.epipolar.any()
        for name in wanted:
            assert np.array_equal(getattr(part, name), getattr(full, name)), name


def _synthetic_views(cams, X, seed: int = 0):
    """Views of the points X, each point with one random unit descriptor (a little noise
    per view), without their poses, and a last view of unrelated descriptors."""
    from bench.frontend.features import Candidates

    rng = np.random.default_rng(seed)
    desc = rng.normal(size=(len(X), 128))
    views, pools = [], []
    for k, cam in enumerate([*cams, cams[0]]):
        last = k == len(cams)
        uv = rng.uniform(0, 480, (len(X), 2)) if last else cam.project(X)[0]
        d = (rng.normal(size=desc.shape) if last else desc) + rng.normal(0, 0.05, desc.shape)
        d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
        n = len(uv)
        pools.append(Candidates(uv, np.full(n, 4.0), np.zeros(n), rng.random(n) + 1, d))
        image = np.zeros((cam.height, cam.width, 3), np.uint8)
        views.append(View(k, f"v{k}.png", image, cam).without_pose())
    return views, pools


def test_geometry_from_the_images_recovers_the_rig_without_reading_it(capsys):
    from bench.frontend.geometry import image_geometry
    from tests.conftest import synthetic_rig

    cams, X = synthetic_rig()
    views, pools = _synthetic_views(cams, X)
    assert not any(v.posed for v in views) and all(
        np.array_equal(v.camera.R, np.eye(3)) for v in views
    )
    geo = image_geometry(views, pools, SignalConfig())
    assert geo.overlap[:4] == [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]] and geo.overlap[4] == []
    for (i, j), (_, b) in geo.pair_frame.items():
        R = cams[j].R @ cams[i].R.T
        t = cams[j].t - R @ cams[i].t
        np.testing.assert_allclose(b.R, R, atol=1e-6)
        np.testing.assert_allclose(b.t, t / np.linalg.norm(t), atol=1e-6)
        F = geo.fundamental(i, j)  # true correspondences lie on their epipolar lines
        xi, xj = cams[i].project(X)[0], cams[j].project(X)[0]
        assert np.diag(epipolar_distances(F, xi, xj)).max() < 1e-3
    assert geo.nearest[0] <= {1, 2, 3} and len(geo.nearest[0]) == 2
    sigs, _ = compute_signals(views, pools, DetectorConfig(), SignalConfig())
    assert sigs[0].parallax.min() > 0 and sigs[0].epipolar.mean() > 0.9
    assert not sigs[4].parallax.any() and not sigs[4].epipolar.any()  # overlaps nothing
    assert "v4.png share(s) too few verified matches with every other view" in (
        capsys.readouterr().err
    )


def test_parallax_from_the_images_follows_the_parallax_from_the_poses():
    """Forward motion: both are low near the epipole (the image centre) and rise outward."""
    from scipy.stats import spearmanr

    from bench.frontend.geometry import image_geometry, rig_geometry

    cams = [look_at((0, y, 0), (0, y + 10, 0), width=400, height=300) for y in (0.0, 1.0)]
    rng = np.random.default_rng(1)
    X = np.c_[rng.uniform(-5, 5, 200), rng.uniform(8, 12, 200), rng.uniform(-3.5, 3.5, 200)]
    views, pools = _synthetic_views(cams, X)
    posed = [replace(v, camera=c, posed=True) for v, c in zip(views, cams)]
    rig = rig_geometry(posed, pools[:2], SignalConfig(depth_prior=10.0))
    est = image_geometry(views[:2], pools[:2], SignalConfig())
    p_rig, p_img = rig.parallax(0, pools[0]), est.parallax(0, pools[0])
    assert p_rig.max() < 1 and spearmanr(p_rig, p_img).statistic > 0.95
    centre = np.linalg.norm(pools[0].xy - [200, 150], axis=1) < 40
    assert p_img[centre].mean() < 0.5 * p_img[~centre].mean()


def test_weights_are_a_vector_keyed_by_signal_name():
    """`--weights 0.3,0.3,0.2,0.1,0.1` was refused (a repeated list item ran once), and the
    weights' order differed from the signals'; each weight now lands on its named signal."""
    import dataclasses

    from bench.cli.run import weights_arg
    from bench.frontend.policies import adaptive_score

    w = weights_arg("0.3,0.3,0.2,0.1,0.15")
    assert dataclasses.asdict(w) == {
        "texture": 0.3,
        "repeatability": 0.3,
        "distinctiveness": 0.2,
        "parallax": 0.1,
        "ambiguity": 0.15,
    }
    for name, weight in dataclasses.asdict(w).items():
        one = Signals(**{s: np.array([float(s == name)]) for s in SIGNALS})
        sign = -1 if name == "ambiguity" else 1
        assert adaptive_score(one, w)[0] == pytest.approx(sign * weight), name


# --- the front end alone: bench frontend ----------------------------------------------


def _frontend(folder, out, *extra) -> int:
    return main(["frontend", "--images", str(folder), "--out", str(out), *extra])


def test_bench_frontend_writes_the_cache_file_front_end_reads(tmp_path, capsys):
    folder, out = photos(tmp_path / "im"), tmp_path / "cache"
    assert _frontend(folder, out) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path.parent == out and path.name.startswith("im-sift-images-") and path.is_file()
    det, sig = DetectorConfig(), SignalConfig()
    fe = front_end(folder, det, sig, out, IMAGES, load_image_folder(folder))
    assert fe.cached and cache_file(folder, det, sig, out, IMAGES) == path
    with np.load(path) as z:
        assert all(np.array_equal(z[f"xy_{v}"], p.xy) for v, p in enumerate(fe.pools))
        assert np.array_equal(z["texture_2"], fe.signals[2].texture)
    assert _frontend(folder, out) == 0
    assert "read from the cache" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == [path.name]


def test_bench_frontend_on_a_dataset_is_what_bench_run_reads(tmp_path, capsys):
    """The front end of a dataset under the rig's geometry, in the cache `bench run` reads
    (RENDERS/frontend/), is what a run's units read: no second computation."""
    from bench.harness.execute import _front_ends
    from bench.unit.config import RunConfig

    ds = tmp_path / "ds"
    photos(ds / "images")
    cams = [look_at((x, -6.0, 1.0), (0.0, 0.0, 1.0), width=160, height=120) for x in (-0.2, 0, 0.2)]
    (ds / "sparse").mkdir()
    write_colmap_rig(cams, ds / "sparse", [f"p{k}.png" for k in range(3)])
    assert _frontend(ds, tmp_path / "renders" / "frontend") == 0
    assert "-sift-rig-" in capsys.readouterr().out
    whole, _ = _front_ends(ds, RunConfig(render=None), tmp_path / "renders", (RIG,))
    assert whole[RIG].cached


@pytest.mark.parametrize(
    "make, extra, said",
    [
        (lambda d: d, (), "image folder {d} does not exist"),
        (lambda d: d.mkdir() or d, (), "{d} holds 0 usable image(s)"),
        (photos, ("--geometry", "rig"), "--geometry rig needs the views' poses"),
        (lambda d: (d / "images").mkdir(parents=True) or d, (), "{d} is neither a render entry"),
    ],
)
def test_bench_frontend_refuses_a_folder_in_one_line(tmp_path, capsys, make, extra, said):
    folder = make(tmp_path / "im")
    assert _frontend(folder, tmp_path / "cache", *extra) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said.format(d=folder) in err
    assert not (tmp_path / "cache").exists()
