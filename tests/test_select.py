"""`bench select` on photographs: the front end of `bench run` (its settings, downscaling,
declared signals), images read whole or refused, and an honest focal length."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pycolmap
import pytest

from bench import BenchError
from bench.camera import look_at
from bench.cli import main
from bench.frontend.features import Candidates, DetectorConfig, detect
from bench.frontend.geometry import SignalConfig, estimate_focal
from bench.frontend.policies import PolicyConfig, PolicyInput
from bench.frontend.selection import select_views
from bench.frontend.stage import compute
from bench.frontend.views import View, load_image_folder, read_image
from tests.conftest import synthetic_rig

PEEKING = """
from bench.frontend.policies import policy
import numpy as np


@policy("peeking", reads=("texture",))
def peeking(inp, budget, rng, cfg):
    return np.argsort(-(inp.signals.texture + inp.signals.epipolar))[:budget]
"""


def texture(height: int, width: int, seed: int = 0) -> np.ndarray:
    """A smooth random texture (SIFT finds many keypoints on it), 8-bit BGR."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (height, width)), (0, 0), 2.0)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


def photos(folder, n=3, size=(160, 120), ext=".png"):
    """`n` overlapping crops of one texture (a plane seen by a sliding camera)."""
    folder.mkdir(parents=True, exist_ok=True)
    big = texture(size[1] + 40, size[0] + 20 * n)
    for k in range(n):
        cv2.imwrite(str(folder / f"p{k}{ext}"), big[20 : 20 + size[1], 20 * k : 20 * k + size[0]])
    return folder


def select(folder, out, *extra):
    return main(["select", "--images", str(folder), "--out", str(out), "--budget", "40", *extra])


@pytest.mark.parametrize("detector", ["orb", "aliked"])
def test_a_pool_without_sift_descriptors_is_refused_in_one_line(tmp_path, capsys, detector):
    folder = photos(tmp_path / "im")
    assert select(folder, tmp_path / "o", "--set", f"detector.detector={detector}") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"detector.detector must be sift, not {detector}" in err[0]
    assert not (tmp_path / "o" / "database.db").exists()


def test_a_truncated_jpeg_is_refused_naming_the_file(tmp_path, capsys):
    folder = photos(tmp_path / "im", ext=".jpg")
    data = (folder / "p1.jpg").read_bytes()
    (folder / "p1.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(BenchError, match="p1.jpg.*truncated"):
        read_image(folder / "p1.jpg")
    assert select(folder, tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "p1.jpg" in err and "truncated" in err
    assert not (tmp_path / "o" / "database.db").exists()


@pytest.mark.parametrize(
    "content, why",
    [
        (b"not an image", "its first bytes (b'not an i') are the signature of no PNG, JPEG"),
        (b"", "the file is empty"),
        ("cut", "its PNG header is followed by data that cannot be decoded"),
    ],
)
def test_a_file_that_is_no_image_is_refused_saying_why(tmp_path, capsys, content, why):
    """A fake `fake.png` was refused as `cannot read image .../fake.png`, with no reason."""
    folder = photos(tmp_path / "im")
    data = (folder / "p0.png").read_bytes()[:100] if content == "cut" else content
    (folder / "fake.png").write_bytes(data)
    assert select(folder, tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{folder / 'fake.png'} is not a readable image: {why}" in err


def test_tiff_and_webp_are_read_and_the_skipped_files_named(tmp_path, capsys):
    folder = photos(tmp_path / "im", n=1)
    img = texture(120, 160, seed=1)
    cv2.imwrite(str(folder / "b.tif"), img)
    cv2.imwrite(str(folder / "c.webp"), img, [cv2.IMWRITE_WEBP_QUALITY, 101])  # lossless
    (folder / "notes.txt").write_text("not an image")
    cv2.imwrite(str(folder / "d.bmp"), img)
    views = load_image_folder(folder)
    assert [v.name for v in views] == ["b.tif", "c.webp", "p0.png"]
    assert np.array_equal(views[0].image, img[..., ::-1])
    assert np.array_equal(views[1].image, img[..., ::-1])
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "skipped 2 file(s)" in err
    assert "d.bmp" in err and "notes.txt" in err


def test_a_guessed_focal_is_an_untrusted_prior_and_is_said(tmp_path, capsys):
    folder = photos(tmp_path / "im")
    assert select(folder, tmp_path / "o") == 0
    assert "no known focal length" in capsys.readouterr().err
    db = pycolmap.Database.open(str(tmp_path / "o" / "database.db"))
    try:
        cams = db.read_all_cameras()
        assert len(cams) == 1 and not cams[0].has_prior_focal_length
    finally:
        db.close()


def test_a_budget_above_the_pools_is_counted_per_image(tmp_path, capsys):
    """`--budget 1000000` said "2998469 short of 1000000 per image": a sum over images
    against a per-image budget. A budget above every pool is refused as `bench run`
    refuses it (it was accepted, up to 1000000000)."""
    folder = photos(tmp_path / "im")
    assert select(folder, tmp_path / "o", "--budget", "1000000000", "--policy", "texture") == 2
    pools = [len(detect(v, DetectorConfig())) for v in load_image_folder(folder)]
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        f"budget 1000000000 exceeds every candidate pool of the 3 image(s) of {folder}" in err[-1]
    )
    assert f"Use budgets up to {max(pools)}" in err[-1] and not (tmp_path / "o").exists()
    budget = max(pools)  # the largest pool alone holds it
    assert select(folder, tmp_path / "o", "--budget", str(budget), "--policy", "texture") == 0
    err = capsys.readouterr().err
    said = f"{sum(pools)} keypoints in 3 images, {budget} per image (fewer in 2 of them: "
    assert said + f"{min(pools)} to {sorted(pools)[1]})" in err and "short of" not in err
    assert f"2 of 3 image(s) have fewer candidates than the budget {budget} per image" in err
    budget = sorted(pools)[1]  # the smallest pool alone falls short
    assert select(folder, tmp_path / "o", "--budget", str(budget), "--policy", "texture") == 0
    said = f"{min(pools) + 2 * budget} keypoints in 3 images, {budget} per image (fewer in 1 "
    assert said + f"of them: {min(pools)})" in capsys.readouterr().err


def _seen(cams, X, seed=0) -> tuple[list[View], list[Candidates]]:
    """Views of the points X by the cameras (focal length guessed, 1.2 x 640) and their
    pools: the projections, with 0.2 px of noise and one descriptor per point."""
    rng = np.random.default_rng(seed)
    desc = rng.normal(size=(len(X), 128)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    views, pools = [], []
    for k, cam in enumerate(cams):
        uv, z = cam.project(X)
        seen = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 640) & (uv[:, 1] >= 0) & (uv[:, 1] < 480)
        uv = uv[seen] + rng.normal(0, 0.2, (seen.sum(), 2))
        n = len(uv)
        pools.append(Candidates(uv, np.full(n, 4.0), np.zeros(n), np.ones(n), desc[seen]))
        f = 1.2 * 640
        guess = look_at((0, 0, 0), (0, 1, 0), width=640, height=480)
        guess = type(guess)(640, 480, f, f, 320, 240, guess.R, guess.t)
        views.append(View(k, f"v{k}", np.zeros((480, 640, 3), np.uint8), guess, False, False))
    return views, pools


def test_the_focal_length_is_estimated_from_a_general_motion():
    """Synthetic correspondences of four cameras whose optical axes do not meet: the
    estimate is the true focal length, the guess is 1.2 x max(width, height)."""
    X = np.random.default_rng(0).uniform(-2, 2, (300, 3)) + [0, 0, 1]
    eyes = [(-3, -8, 1.5), (-1, -8.5, 0.5), (1.5, -7.5, 2), (3, -8, 1)]
    targets = [(0.8, 0, 1.3), (-0.6, 0.5, 0.7), (0.4, -0.7, 1.8), (-1, 0.3, 0.5)]
    cams = [look_at(e, t, width=640, height=480, fov_x_deg=55) for e, t in zip(eyes, targets)]
    found = estimate_focal(*_seen(cams, X), SignalConfig())
    assert found.pairs == 6 and found.why == ""
    assert found.factor * 640 == pytest.approx(cams[0].fx, rel=0.02)
    best, off = found.explained
    assert best >= 1.5 * off


def test_a_focal_length_the_views_do_not_determine_is_not_estimated():
    """Four cameras looking at one point (their optical axes meet: a critical motion) gave
    a focal length far off the truth; now the guess stays, and the line says why."""
    cams, X = synthetic_rig()
    found = estimate_focal(*_seen(cams, X), SignalConfig())
    assert found.factor is None and found.pairs == 6
    best, off = found.explained
    assert best < 1.5 * off and found.why.startswith(f"their relative poses explain {best} ")
    assert "views whose optical axes meet" in found.why
    few = estimate_focal(*_seen(cams[:2], X), SignalConfig())
    assert few.factor is None and few.why == "1 pair(s) of images share 15 matches, 2 needed"


@pytest.mark.parametrize("turn_deg", [0.0, 2.0])
def test_a_focal_length_is_not_estimated_from_forward_motion_and_the_line_says_so(turn_deg):
    """Driving forward (KITTI's motion) the optical axes lie along the motion, which leaves
    the focal length undetermined as a ring does (on `kitti-seq2` every window of frames
    was); the guess stays, and the line names forward motion, not a ring alone."""
    rng = np.random.default_rng(1)
    y, side = rng.uniform(6, 40, 600), rng.choice([-4.0, 4.0], 600)  # a street's walls
    X = np.c_[side + rng.normal(0, 0.2, 600), y, rng.uniform(0, 4, 600)]
    yaw = np.radians(turn_deg * np.arange(4))  # 1 m a frame, turning by turn_deg a frame
    heading = np.c_[np.sin(yaw), np.cos(yaw), np.zeros(4)]
    eyes = np.cumsum(heading, axis=0) - heading + [0, 0, 1.6]
    cams = [look_at(e, e + 10 * h, fov_x_deg=82) for e, h in zip(eyes, heading)]
    found = estimate_focal(*_seen(cams, X), SignalConfig())
    assert found.factor is None and found.pairs == 6
    assert "or lie along the motion, as driving forward" in found.why


def test_a_database_already_in_out_is_kept_under_the_name_said(tmp_path, capsys):
    """A second `bench select --out` into a folder replaced its database.db ("replacing
    ..."): the first one was lost."""
    folder, out = photos(tmp_path / "im"), tmp_path / "o"
    assert select(folder, out, "--policy", "texture") == 0
    first = (out / "database.db").read_bytes()
    for n in (1, 2):
        capsys.readouterr()
        assert select(folder, out, "--policy", "random") == 0
        said = f"{out / 'database.db'} already existed: kept as {out / f'database.{n}.db'}"
        assert said in capsys.readouterr().err
    assert (out / "database.1.db").read_bytes() == first
    assert sorted(p.name for p in out.iterdir()) == [
        "database.1.db",
        "database.2.db",
        "database.db",
    ]


def test_out_file_is_refused_before_any_work(tmp_path, capsys):
    folder = photos(tmp_path / "im")
    (folder / "broken.png").write_bytes(b"not an image")  # would be refused on reading
    (tmp_path / "file").write_text("x")
    assert select(folder, tmp_path / "file") == 2
    assert "is a file; give a folder" in capsys.readouterr().err


def test_sigterm_stops_select_in_one_line(tmp_path):
    """SIGTERM (`timeout`, systemd) during `bench select` printed COLMAP's native stack
    (glog's failure handler, installed when pycolmap is first imported, after ours)."""
    import signal
    import subprocess
    import sys
    import time

    mark = tmp_path / "selecting"
    module = tmp_path / "sleepy.py"
    module.write_text(
        "import pathlib, time\n"
        "from bench.frontend.policies import policy\n\n"
        "@policy('sleepy')\n"
        "def sleepy(inp, budget, rng, cfg):\n"
        f"    pathlib.Path({str(mark)!r}).touch()\n"
        "    time.sleep(60)\n"
    )
    cmd = [sys.executable, "-m", "bench", "select", "--images", str(photos(tmp_path / "im"))]
    cmd += ["--out", str(tmp_path / "o"), "--policy", "sleepy", "--policy-module", str(module)]
    cmd += ["--budget", "40"]  # within the pools (a budget above every pool is refused)
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while not mark.exists() and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    lines = err.strip().splitlines()
    assert proc.returncode == 143 and lines[-1] == "bench: terminated; finished work is kept"
    assert all(line.startswith("bench: ") for line in lines), err
    assert not (tmp_path / "o" / "database.db").exists()


def test_an_undeclared_signal_is_refused_in_run_and_select(tmp_path, capsys):
    module = tmp_path / "peek.py"
    module.write_text(PEEKING)
    folder = photos(tmp_path / "im")
    assert (
        select(folder, tmp_path / "o", "--policy", "peeking", "--policy-module", str(module)) == 2
    )
    last = capsys.readouterr().err.splitlines()[-1]
    assert "policy peeking reads the signal 'epipolar', which it did not declare" in last
    # `bench run`'s selection: every signal computed, the same refusal
    views, pools, sigs, _ = compute(load_image_folder(folder), DetectorConfig(), SignalConfig())
    inputs = [PolicyInput(v, c, s) for v, c, s in zip(views, pools, sigs)]
    assert sigs[0].epipolar.shape == (len(pools[0]),)
    with pytest.raises(BenchError, match="'epipolar', which it did not declare"):
        select_views("peeking", inputs, 20, 0, PolicyConfig(modules=(str(module),)), None)


def test_select_takes_the_settings_and_downscales_as_run_does(tmp_path, capsys):
    folder = photos(tmp_path / "im", size=(320, 240))
    out = tmp_path / "o"
    assert select(folder, out, "--policy", "all", "--set", "detector.max_image_size=160") == 0
    err = capsys.readouterr().err
    assert "the whole pool" in err and "short" not in err
    small = [detect(v.scale_to(160)[0], DetectorConfig()) for v in load_image_folder(folder)]
    db = pycolmap.Database.open(str(out / "database.db"))
    try:
        kps = [db.read_keypoints(k + 1) for k in range(3)]
    finally:
        db.close()
    assert [len(k) for k in kps] == [len(c) for c in small]
    for k, c in zip(kps, small):  # detected at half size, kept in full-resolution pixels
        assert np.allclose(k[:, :2], c.xy * 2, atol=1e-3)
    assert select(folder, out, "--policy", "all", "--max-candidates", "25") == 0
    assert (
        select(folder, tmp_path / "s", "--policy", "all", "--set", "detector.max_features=25") == 0
    )
    for o in (out, tmp_path / "s"):
        db = pycolmap.Database.open(str(o / "database.db"))
        try:
            assert db.num_keypoints() == 3 * 25
        finally:
            db.close()
