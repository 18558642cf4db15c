"""Scoring without waste (issue 29): exact point-to-surface distances that stay fast far from
the surface, one point-error computation per model, one checksum per render entry per
process, images decoded once per scene and only when a front end is computed."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from bench import BenchError, files
from bench.evaluation import truth as truth_module
from bench.evaluation.layers import read_layers
from bench.evaluation.metrics import point_error, point_metrics
from bench.evaluation.truth import SceneTruth, Surface
from bench.frontend import views as views_module
from bench.frontend.geometry import IMAGES, RIG
from bench.frontend.stage import front_end
from bench.frontend.views import Source, source_key
from bench.harness import execute
from bench.harness.execute import Work, compute_unit
from bench.results import Workspace
from bench.unit.config import RunConfig
from bench.unit.predict import LoadedScene
from bench.vocabulary import Job, Unit

# --- exact distances ---------------------------------------------------------------


def _samples(rng) -> np.ndarray:
    """A floor, a wall and a sphere, sampled as a render's surface is (dense, float32)."""
    u, v = rng.uniform(-3, 3, (2, 6000))
    floor = np.c_[u, v, np.zeros_like(u)]
    wall = np.c_[u, np.full_like(u, 3.0), 1.5 + v / 2]
    d = rng.normal(size=(3000, 3))
    ball = 0.5 * d / np.linalg.norm(d, axis=1, keepdims=True) + [0, 0, 1]
    return np.concatenate([floor, wall, ball]).astype(np.float32).astype(np.float64)


def _queries(S: np.ndarray, rng) -> np.ndarray:
    """Points on, near and far (up to 40 units) from the surface, and hand-made ones: a
    sample itself, the sphere's centre (equidistant from all of it), points outside every
    box and between the blocks."""
    d = rng.normal(size=(1500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.r_[rng.uniform(0, 0.05, 500), rng.uniform(0.05, 2, 500), rng.uniform(2, 40, 500)]
    X = S[rng.integers(0, len(S), 1500)] + d * r[:, None]
    hand = [S[0], S[-1], [0, 0, 1], [0, -30, 1], [40, 40, 40], [0, 0, -7], [3, 3, 3], [0, 1.5, 0.5]]
    return np.r_[X, hand]


@pytest.mark.parametrize("block", [16, 256, 16384])
def test_surface_distances_equal_an_unbounded_k_d_tree_to_the_last_bit(monkeypatch, block):
    monkeypatch.setattr(truth_module, "BLOCK", block)
    rng = np.random.default_rng(block)
    S = _samples(rng)
    X = _queries(S, rng)
    surface = Surface(S)
    assert len(surface.trees) >= len(S) // block // 2
    got = surface.distances(X)
    assert np.array_equal(got, cKDTree(S).query(X)[0])  # bit for bit
    brute = np.array([np.sqrt(((S - x) ** 2).sum(1)).min() for x in X])
    np.testing.assert_allclose(got, brute, rtol=1e-12, atol=0)
    assert got[-8:-6].tolist() == [0.0, 0.0]  # the samples themselves


def test_surface_distances_of_nothing_and_to_nothing():
    surface = Surface(np.array([[0.0, 0, 0], [1, 0, 0]]))
    assert point_error(np.zeros((0, 3)), surface).shape == (0,)
    assert surface.distances([[0, 3, 4]]).tolist() == [5.0]
    assert np.isinf(Surface(np.zeros((0, 3))).distances([[1.0, 2, 3]])).all()


def test_point_metrics_are_unchanged_far_from_the_surface(monkeypatch):
    """rmse, median and every threshold on points near and far, against the k-d tree."""
    monkeypatch.setattr(truth_module, "BLOCK", 64)
    rng = np.random.default_rng(7)
    S = _samples(rng)
    X = _queries(S, rng)
    e = cKDTree(S).query(X)[0]
    got = point_metrics(X, Surface(S), (X, np.full(len(X), 1e-9)))  # each point a track
    assert got["rmse"] == float(np.sqrt(np.mean(e**2)))
    assert got["median_error"] == float(np.median(e))
    assert got["accuracy_pct"] == 100.0 * float(np.mean(e < 0.10))
    assert got["acc_completeness_pct_0.02"] == 100.0 * float(np.sum(e < 0.02)) / len(X)


# --- one point-error computation per model ------------------------------------------


@pytest.fixture
def counted_nearest(monkeypatch):
    calls = []
    real = Surface._nearest

    def counting(self, X, *a):
        calls.append(len(X))
        return real(self, X, *a)

    monkeypatch.setattr(Surface, "_nearest", counting)
    return calls


def test_a_tri_model_has_its_point_errors_computed_once(medium_entry, tmp_path, counted_nearest):
    entry = medium_entry("table")
    cfg = RunConfig()
    fe = front_end(entry, cfg.detector, cfg.signals, tmp_path / "fe")
    truth = SceneTruth.build([v.camera for v in fe.views], read_layers(entry), fe.pools)
    unit, work = Unit("table", 0, "texture", 128), Work((Job("tri", "multiview"),))
    (row,) = compute_unit(
        LoadedScene(entry, {RIG: fe}, truth), unit, work, cfg, Workspace(tmp_path, tmp_path)
    )
    assert row["status"] == "ok" and row["points"] > 0
    assert counted_nearest == [row["points"]]  # the scores and point_errors.csv
    csv = tmp_path / "models" / "table-s0" / "texture-b128" / "point_errors.csv"
    errors = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1]
    assert len(errors) == row["points"]
    assert float(np.median(errors)) == pytest.approx(row["median_error"], rel=1e-5)


# --- one checksum per render entry per process -----------------------------------------


@pytest.fixture
def entry_copy(tiny_entry, tmp_path):
    copy = tmp_path / tiny_entry("table").name
    shutil.copytree(tiny_entry("table"), copy)
    return copy


def test_a_render_entry_is_checksummed_once_per_process(entry_copy, monkeypatch):
    sums = []
    real = files.checksum
    monkeypatch.setattr(files, "checksum", lambda p: sums.append(p.name) or real(p))
    listed = len([p for p in entry_copy.iterdir() if p.name != "meta.json"])
    for _ in range(10):  # what a unit's rows did: each access checksummed every file
        assert files.entry_problem(entry_copy) is None
        Source.of(entry_copy)
        source_key(entry_copy)
    assert len(sums) == listed


def test_a_damaged_entry_is_caught_after_it_was_verified(entry_copy):
    assert files.entry_problem(entry_copy) is None
    png = entry_copy / "view_01.png"
    blob = bytearray(png.read_bytes())
    blob[len(blob) // 2] ^= 0xFF  # same size, other bytes
    png.write_bytes(bytes(blob))
    assert "view_01.png altered" in files.entry_problem(entry_copy)


def test_each_process_verifies_an_entry_on_its_first_access(entry_copy):
    """Damage that keeps a file's size and time escapes the memo of this process (which
    verified the entry before), never a new process's first access."""
    assert files.entry_problem(entry_copy) is None
    gt = entry_copy / "gt_02.npz"
    st = gt.stat()
    blob = bytearray(gt.read_bytes())
    blob[-100] ^= 0xFF
    gt.write_bytes(bytes(blob))
    os.utime(gt, ns=(st.st_atime_ns, st.st_mtime_ns))
    code = f"from pathlib import Path; from bench.files import entry_problem as p; print(p(Path({str(entry_copy)!r})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "gt_02.npz altered" in out.stdout


# --- images decoded once per scene, after the front-end cache lookup ------------------


def test_images_are_decoded_once_per_scene_and_not_on_a_cache_hit(
    tiny_entry, tmp_path, monkeypatch
):
    entry = tiny_entry("table")
    decoded = []
    real = views_module.read_image
    monkeypatch.setattr(views_module, "read_image", lambda p: decoded.append(p.name) or real(p))
    cfg = RunConfig()
    _, fronts = execute._front_ends(entry, cfg, tmp_path, (IMAGES, RIG))  # computed
    assert sorted(decoded) == [f"view_{v:02d}.png" for v in range(6)]
    assert not any(f.cached for f in fronts.values())
    decoded.clear()
    _, fronts = execute._front_ends(entry, cfg, tmp_path, (IMAGES, RIG))  # read from the cache
    scene = execute._scene(entry, cfg, tmp_path, (IMAGES, RIG))
    assert all(f.cached for f in fronts.values()) and scene.truth.surface is not None
    assert decoded == []
    assert fronts[IMAGES].views[2].image.shape == (72, 96, 3)  # decoded when asked for
    assert fronts[RIG].views[2].image is fronts[IMAGES].views[2].image
    assert decoded == ["view_02.png"]
    execute._HELD.clear()


def test_an_image_of_another_size_than_its_camera_is_refused_when_decoded(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((8, 10, 3), np.uint8))
    image = views_module.ImageFile(tmp_path / "a.png", 12, 8)
    with pytest.raises(BenchError, match=r"a.png is 10x8, its camera says 12x8$"):
        image()
    assert views_module.ImageFile(tmp_path / "a.png", 10, 8)().shape == (8, 10, 3)
