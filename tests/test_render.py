"""The render stage: camera convention, ground truth, determinism, cache, variant choice."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from bench import BenchError, files
from bench.camera import look_at
from bench.cli import main
from bench.render import entry as render
from bench.render import mitsuba, variant
from bench.scenes.catalog import build_scene, load_spec, scene_names
from tests.conftest import TINY, default_sigint, rig


@pytest.mark.parametrize("scene", scene_names())
def test_ground_truth_projects_onto_its_pixels(tiny_entry, scene):
    assert_ground_truth_projects(tiny_entry(scene), TINY.views)


def test_views_sets_the_rig_and_enters_the_render_key(tiny_entry, renders_dir):
    three = render.render_scene("facade", 0, replace(TINY, views=3), renders_dir)
    assert three.name != tiny_entry("facade").name
    assert json.loads((three / "meta.json").read_text())["views"] == 3
    assert_ground_truth_projects(three, 3)
    path = [c.center for c in rig(three)]
    six = [c.center for c in rig(tiny_entry("facade"))]
    np.testing.assert_allclose([path[0], path[-1]], [six[0], six[-1]])  # the same path
    with pytest.raises(BenchError, match="views must be at least 2"):
        render.render_scene("facade", 0, replace(TINY, views=1), renders_dir)


@pytest.mark.parametrize("scene", scene_names())
def test_a_denser_rig_on_the_same_path_holds_the_sparser_one(scene):
    """Every third view of a 7-view rig is a view of the 3-view rig on the same path: the
    same camera, and the same leaves in the wind (the scene is otherwise the same)."""
    desc3, desc7 = (build_scene(load_spec(scene), 0, 48, 36, n) for n in (3, 7))
    for a, b in ((0, 0), (1, 3), (2, 6)):
        np.testing.assert_array_equal(desc3.cameras[a].R, desc7.cameras[b].R)
        np.testing.assert_array_equal(desc3.cameras[a].t, desc7.cameras[b].t)
    assert not np.array_equal(desc3.cameras[1].t, desc7.cameras[1].t)
    for m3, m7 in zip(desc3.meshes, desc7.meshes, strict=True):
        np.testing.assert_array_equal(m3.vertices, m7.vertices)
        assert (m3.motion is None) == (m7.motion is None)
        if m3.motion is not None:
            np.testing.assert_array_equal(m3.motion, m7.motion[::3])


def test_the_views_two_rigs_share_are_rendered_once(tmp_path):
    """A 3-view and a 5-view rig of one path: views 0, 2, 4 of the second are linked from
    the per-view cache (the same pixels and ground truth), only two are rendered."""
    small = replace(TINY, width=48, height=36, spp=2)
    three = render.render_scene("vegetation", 0, replace(small, views=3), tmp_path)
    assert len(list((tmp_path / "views").iterdir())) == 3
    five = render.render_scene("vegetation", 0, replace(small, views=5), tmp_path)
    assert len(list((tmp_path / "views").iterdir())) == 5
    for a, b in ((0, 0), (1, 2), (2, 4)):
        for name in ("view_{:02d}.png", "gt_{:02d}.npz"):
            assert (three / name.format(a)).read_bytes() == (five / name.format(b)).read_bytes()
    assert (three / "view_01.png").read_bytes() != (five / "view_01.png").read_bytes()
    # a view's pixels do not depend on which rig rendered it first (its noise is seeded by
    # its path position, not its index in the rig)
    alone = render.render_scene("vegetation", 0, replace(small, views=5), tmp_path / "b")
    assert (alone / "view_02.png").read_bytes() == (three / "view_01.png").read_bytes()


def assert_ground_truth_projects(entry, views: int) -> None:
    """Every view's single-surface pixels project back onto themselves, and its range and
    z-depth agree with its intrinsics."""
    cams = rig(entry)
    assert len(cams) == views
    for v, cam in enumerate(cams):
        gt = np.load(entry / f"gt_{v:02d}.npz")
        si = gt["shape_index"]
        interior = (si >= 0) & (si == np.round(si))  # one surface over the whole pixel
        vv, uu = np.nonzero(interior)
        uv, z = cam.project(gt["position"][vv, uu].astype(float))
        centres = np.stack([uu + 0.5, vv + 0.5], 1)
        err = np.linalg.norm(uv - centres, axis=1)
        assert interior.mean() > 0.5
        assert np.median(err) < 0.1, f"view {v}: median reprojection error {np.median(err):.3f} px"
        # range and z-depth agree with the exported intrinsics: range / z = |K^-1 (u, v, 1)|
        ray = np.stack([(centres[:, 0] - cam.cx) / cam.fx, (centres[:, 1] - cam.cy) / cam.fy], 1)
        expect = np.sqrt(1 + (ray**2).sum(1))
        ratio = gt["range"][vv, uu] / gt["z"][vv, uu]
        assert np.median(np.abs(ratio / expect - 1)) < 2e-3
        np.testing.assert_allclose(z, gt["z"][vv, uu], rtol=1e-4)


def test_mitsuba_sensor_is_the_only_conversion():
    cam = look_at((1.0, -5.0, 2.0), (0.0, 0.0, 1.0), width=64, height=48, fov_x_deg=50)
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    sensor = mi.load_dict(mitsuba.mitsuba_sensor(cam, 1))
    M = np.array(sensor.world_transform().matrix)
    np.testing.assert_allclose(M[:3, 3], cam.center, atol=1e-5)
    # Mitsuba looks down its +z, which must be the OpenCV camera's +z (forward)
    np.testing.assert_allclose(M[:3, 2], cam.R[2], atol=1e-5)


@pytest.mark.parametrize("scene", scene_names())
def test_same_seed_same_scene_other_seed_differs(scene):
    spec = load_spec(scene)
    a, b, c = (build_scene(spec, s, 64, 48, 6) for s in (3, 3, 4))

    def fingerprint(d):
        return [
            (
                m.name,
                m.vertices.tobytes(),
                None if m.material.texture is None else m.material.texture.tobytes(),
            )
            for m in d.meshes
        ]

    assert fingerprint(a) == fingerprint(b)
    assert fingerprint(a) != fingerprint(c)


def test_rendering_is_deterministic(tmp_path):
    a = render.render_scene("table", 1, TINY, tmp_path / "a")
    b = render.render_scene("table", 1, TINY, tmp_path / "b")
    assert a.name == b.name
    for v in (0, 5):
        assert np.array_equal(
            cv2.imread(str(a / f"view_{v:02d}.png")), cv2.imread(str(b / f"view_{v:02d}.png"))
        )


@pytest.fixture
def counted(monkeypatch):
    calls = []
    real = render.render_view

    def wrapper(desc, view, cfg, var):
        calls.append(view)
        return real(desc, view, cfg, var)

    monkeypatch.setattr(render, "render_view", wrapper)
    return calls


def test_cache_hit_renders_nothing(tiny_entry, renders_dir, counted):
    entry = tiny_entry("table")
    assert render.render_scene("table", 0, TINY, renders_dir) == entry
    assert counted == []


def test_damaged_entry_is_detected_and_rendered_again(tmp_path, counted, capsys):
    """A damaged entry is made again; only a view whose pixels or ground truth are damaged
    (in the entry and in the per-view cache it is linked from) is rendered again."""
    entry = render.render_scene("table", 2, TINY, tmp_path)
    assert counted == list(range(6))
    gt = entry / "gt_03.npz"
    gt.write_bytes(gt.read_bytes()[:100])  # truncated (the per-view cache's file with it)
    assert render.render_scene("table", 2, TINY, tmp_path) == entry
    assert counted[6:] == [3] and "damaged cache entry" in capsys.readouterr().err
    np.load(entry / "gt_03.npz")["position"]  # whole again
    (entry / "view_01.png").unlink()  # the per-view cache still has it: linked again
    render.render_scene("table", 2, TINY, tmp_path)
    assert counted[7:] == [] and (entry / "view_01.png").is_file()
    (entry / "meta.json").write_text("{not json")
    render.render_scene("table", 2, TINY, tmp_path)
    assert counted[7:] == [] and json.loads((entry / "meta.json").read_text())["seed"] == 2
    # hole 6 of issue 10: a view overwritten with other bytes of the same size
    png = entry / "view_01.png"
    png.write_bytes(
        np.random.default_rng(0).integers(0, 256, png.stat().st_size, np.uint8).tobytes()
    )
    render.render_scene("table", 2, TINY, tmp_path)
    assert counted[7:] == [1] and "view_01.png altered" in capsys.readouterr().err
    assert cv2.imread(str(png)) is not None


def test_interrupted_render_leaves_no_entry(tmp_path, monkeypatch):
    real = render.render_view

    def dies_at_view_3(desc, view, cfg, var):
        if view == 3:
            raise KeyboardInterrupt
        return real(desc, view, cfg, var)

    monkeypatch.setattr(render, "render_view", dies_at_view_3)
    with pytest.raises(KeyboardInterrupt):
        render.render_scene("table", 5, TINY, tmp_path)
    # no rig entry; the three views rendered before the interruption are kept, whole
    assert [p.name for p in tmp_path.iterdir() if not p.name.startswith(".")] == ["views"]
    assert_no_partial_work(tmp_path, views=3)


def assert_no_partial_work(renders: Path, views: int | None = None) -> None:
    """No temporary folder or lock file is left (issue 10, hole 7) in a renders folder or
    its per-view cache, and every cached view is whole (`views`: how many)."""
    for folder in (renders, renders / "views"):
        assert not list(folder.glob(".tmp-*")) and not list(folder.glob(".*.lock"))
    kept = sorted((renders / "views").glob("[!.]*")) if (renders / "views").is_dir() else []
    assert all(files.entry_problem(v) is None for v in kept)
    assert views is None or len(kept) == views


def test_two_processes_rendering_one_entry(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "bench",
        "render",
        "table",
        "--seed",
        "6",
        "--renders",
        str(tmp_path),
    ]
    cmd += ["--width", "48", "--height", "36", "--spp", "4", "--max-depth", "2"]
    procs = [
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    assert outs[0][0] == outs[1][0]  # the same entry
    assert sum(err.count("rendered table") for _, err in outs) == 6  # rendered once
    from pathlib import Path

    from bench.files import entry_problem

    assert entry_problem(Path(outs[0][0].strip())) is None


def test_variant_probe_abort_falls_back_to_scalar(tmp_path, monkeypatch):
    monkeypatch.setattr(variant, "PROBE_CODE", "import os; os.abort()")
    monkeypatch.setattr(variant, "_gpu_present", lambda: False)
    chosen, why = variant.resolve_variant("auto", tmp_path)
    assert chosen == "scalar_rgb" and "fallback" in why and "\n" not in why
    with pytest.raises(BenchError, match="does not render here"):
        variant.resolve_variant("llvm_ad_rgb", tmp_path)
    # the answer is remembered: a second call does not probe again
    monkeypatch.setattr(variant, "probe", lambda v: pytest.fail("probed twice"))
    assert variant.resolve_variant("auto", tmp_path)[0] == "scalar_rgb"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["render", "nope"], "unknown scene 'nope'; valid: "),
        (["render", "table", "--spp", "0"], "spp must be positive"),
        (["render", "table", "--width", "-4"], "width must be positive"),
        (["render", "table", "--variant", "optix"], "invalid choice: 'optix'"),
    ],
)
def test_cli_bad_input_is_one_clear_line(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        sys.exit(main([*argv, "--renders", str(tmp_path / "r")]))
    assert e.value.code != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").glob("table-*"))


def test_cli_unwritable_output_directory(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    argv = ["render", "table", "--width", "8", "--height", "8", "--spp", "1"]
    with pytest.raises(SystemExit) as e:
        main([*argv, "--renders", str(blocker / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and err[-1].startswith("bench: error: argument --renders: ")
    assert f"{blocker} in {blocker / 'r'} is a file; give a folder" in err[-1]


def test_scalar_fallback_renders_the_same_layout(tmp_path):
    cfg = type(TINY)(width=32, height=24, spp=4, max_depth=2, variant="scalar_rgb")
    entry = render.render_scene("vegetation", 0, cfg, tmp_path)
    meta = json.loads((entry / "meta.json").read_text())
    assert meta["variant"] == "scalar_rgb"
    gt = np.load(entry / "gt_00.npz")
    assert gt["position"].shape == (24, 32, 3) and np.isfinite(gt["range"]).mean() > 0.9


@pytest.mark.parametrize("sig, code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_during_a_render_leaves_no_lock_or_temporary_folder(tmp_path, sig, code):
    """`bench render` stopped mid-render (once its temporary folder exists) exits with the
    signal's code and one line, and leaves neither its lock file nor a `.tmp-` folder."""
    import signal
    import time

    cmd = [sys.executable, "-m", "bench", "render", "table", "--seed", "5", "--width", "96"]
    cmd += ["--height", "72", "--spp", "64", "--renders", str(tmp_path)]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".tmp-*")) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.05)
    proc.send_signal(getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1].startswith("bench: ")
    assert {p.name for p in tmp_path.iterdir()} - {"views"} == {".variant-probes.json"}
    assert_no_partial_work(tmp_path)


def test_a_signal_between_a_temporary_folder_and_its_block_leaves_no_folder(tmp_path, monkeypatch):
    """A signal after `atomic_dir` made its temporary folder and before its block began left
    the folder behind (the test above, once in a fresh clone: `views/.tmp-table-s5-...`)."""
    from bench import files

    made = files.temp_dir_beside

    def interrupted(target):
        made(target)
        raise KeyboardInterrupt

    monkeypatch.setattr(files, "temp_dir_beside", interrupted)
    with pytest.raises(KeyboardInterrupt), files.atomic_dir(tmp_path / "entry"):
        pass
    assert list(tmp_path.iterdir()) == []


def test_the_developing_step_enters_the_key_and_leaves_the_ground_truth(tiny_entry, renders_dir):
    raw = tiny_entry("table")
    developed = render.render_scene("table", 0, replace(TINY, denoise=3.0), renders_dir)
    assert developed.name != raw.name
    for v in (0, 3):
        a, b = (np.load(e / f"gt_{v:02d}.npz") for e in (raw, developed))
        for layer in a.files:
            np.testing.assert_array_equal(a[layer], b[layer])
        img = [cv2.imread(str(e / f"view_{v:02d}.png")).astype(int) for e in (raw, developed)]
        assert 0 < np.abs(img[0] - img[1]).mean() < 10  # denoised, not another picture
    with pytest.raises(BenchError, match="denoise must be at least 0"):
        render.render_scene("table", 0, replace(TINY, denoise=-1.0), renders_dir)
