"""Real photographs in, COLMAP databases out: image folders, datasets in the COLMAP layout,
`bench export`, `bench run --dataset` and `bench select`."""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pycolmap
import pytest
from scipy.spatial import cKDTree

from bench import BenchError
from bench.backend.matching import BackendConfig
from bench.backend.reconstruction import fixed_intrinsics_options
from bench.binding import read_vocabulary
from bench.camera import Camera, look_at, write_colmap_rig
from bench.cli import main
from bench.evaluation.export import export_dataset
from bench.frontend import formats
from bench.frontend.colmap_model import read_model, read_reconstruction
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.geometry import RIG, SignalConfig
from bench.frontend.stage import front_end
from bench.frontend.views import Source, load_image_folder, load_views, source_key
from bench.harness.grid import BenchConfig
from bench.harness.select import SelectRequest, select_to_database
from bench.report.transfer import transfer
from bench.runs import read_runs
from bench.unit.config import RunConfig
from bench.vocabulary import KEY
from tests.conftest import MEDIUM, bench_run, rows_of

GRID = dict(
    seeds=(0,), methods=("texture", "grid", "adaptive", "oracle", "colmap-b"), budgets=(64,)
)
NOT_COMPARED = {"scene", "render_key", "pixels", "render_s_per_view", "invocation", "ground_truth"}
NOT_COMPARED |= {"row_checksum"}  # a hash of every value, those above included


@pytest.fixture(scope="module")
def dataset(medium_entry, tmp_path_factory):
    return export_dataset(medium_entry("table"), tmp_path_factory.mktemp("ds") / "table-ds")


def test_export_has_the_colmap_layout_and_reads_back(dataset, medium_entry):
    assert sorted(p.name for p in (dataset / "images").iterdir()) == [
        f"view_{k:02d}.png" for k in range(6)
    ]
    names = [n for n, _ in read_model(dataset / "sparse")]
    assert names == [n for n, _ in read_model(medium_entry("table"))]
    assert (dataset / "ground_truth" / "points.ply").is_file()
    with pytest.raises(BenchError, match="not an earlier export"):
        export_dataset(medium_entry("table"), dataset / "images")


def test_dataset_run_gives_the_metrics_and_the_ranking_of_the_rendered_path(
    dataset, quick_results, renders_dir, tmp_path
):
    # the rendered path: the small grid's rows of these units (run for the session in one
    # process, at these settings), whole rows (their checksums hold) in a folder of their own
    run = RunConfig(render=MEDIUM)

    def ours(rows):
        return (rows["scene"] == "table") & rows["method"].isin(GRID["methods"])

    rendered = read_runs(rows_of(quick_results, tmp_path / "r", ours) / "runs.csv")
    settings = json.loads((tmp_path / "r" / "config.json").read_text())["settings"]
    assert settings == json.loads(json.dumps(run.as_dict()))  # the settings the dataset runs
    data = bench_run(
        BenchConfig(scenes=(dataset.name,), run=run, datasets=(str(dataset),), **GRID),
        tmp_path / "d",
        renders_dir,
        workers=1,
    )
    assert len(rendered) == len(data) == 4 * 5 + 3  # tri, sfm x 2 protocols, pairs once; colmap-b
    timing = {c for c in rendered if c.endswith("_ms")}
    cols = [c for c in rendered.columns if c not in NOT_COMPARED | timing]
    a = rendered[cols].sort_values(list(KEY[2:]), ignore_index=True)
    b = data[cols].sort_values(list(KEY[2:]), ignore_index=True)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-6, check_dtype=False)
    assert a["acc_completeness_pct"].notna().any() and a["maa"].notna().any()
    # the export of a render ranks the methods as the render does, each category of `sees`
    # apart: texture, grid and colmap-b see their image (tri has no peer: 2, unranked);
    # adaptive alone sees other views
    summary, ranks = transfer(data, read_vocabulary(tmp_path / "d"), tmp_path / "r")
    assert set(summary["metric"]) == {"sfm_maa", "pairs_auc_10"}
    assert set(summary["sees"]) == {"image"} and set(ranks["method"]) == {
        "texture",
        "grid",
        "colmap-b",
    }
    assert (ranks["rank_shift"] == 0).all() and len(ranks) == 3 + 3
    assert summary["kendall_tau"].isna().all()  # 3 methods: too few for a tau
    assert summary["tau_note"].str.match(r"no tau: 3 methods, too few").all()
    assert (summary["winner_dataset"] == summary["winner_rendered"]).all()


METHODS6 = [f"m{k}" for k in range(1, 7)]


@pytest.mark.parametrize(
    "dataset, lower_better, tau, winner, ranks",
    [  # rendered: m1 best (highest) ... m6 worst
        ([1, 2, 3, 4, 5, 6], False, -1.0, "m6", [6, 5, 4, 3, 2, 1]),  # reversed
        ([6, 5, 4, 2, 3, 1], False, 13 / 15, "m1", [1, 2, 3, 5, 4, 6]),  # one pair swapped
        ([6, 6, 4, 3, 2, 1], False, 14 / (14 * 15) ** 0.5, "m1=m2", [1.5, 1.5, 3, 4, 5, 6]),
    ],
)
def test_transfer_ranks_best_first_and_tau_has_its_known_value(
    dataset, lower_better, tau, winner, ranks
):
    """Hand-made means of six methods against a rendered ranking m1 > m2 > ... > m6."""
    from bench.report.transfer import compare

    rendered = pd.Series([6.0, 5, 4, 3, 2, 1], index=METHODS6)
    row, rows = compare(pd.Series(dataset, index=METHODS6, dtype=float), rendered, lower_better)
    assert row["kendall_tau"] == pytest.approx(tau) and row["tau_note"] == ""
    assert row["tau_lo"] <= row["kendall_tau"] <= row["tau_hi"]
    assert row["winner_dataset"] == winner and row["winner_rendered"] == "m1"
    assert [r["rank_dataset"] for r in rows] == ranks
    assert [r["rank_rendered"] for r in rows] == [1, 2, 3, 4, 5, 6]


def test_transfer_of_a_lower_is_better_metric_ranks_the_smallest_first():
    from bench.report.transfer import compare

    errors = pd.Series([0.1, 0.2, 0.3, 0.4, 0.6, 0.5], index=METHODS6)
    row, rows = compare(errors, errors * 10, lower_better=True)
    assert row["winner_dataset"] == row["winner_rendered"] == "m1"
    assert [r["rank_dataset"] for r in rows] == [1, 2, 3, 4, 6, 5] and row["kendall_tau"] == 1
    row, rows = compare(errors, errors[::-1].set_axis(METHODS6), lower_better=True)
    assert row["winner_rendered"] == "m6" and row["kendall_tau"] == pytest.approx(-11 / 15)


def test_transfer_below_six_methods_gives_no_tau_and_says_why():
    """Three methods gave tau -1 with a "95 %" interval [-1, -1] and no warning."""
    from bench.report.transfer import compare

    three = list("abc")
    row, rows = compare(pd.Series([1.0, 2, 3], three), pd.Series([3.0, 2, 1], three), False)
    assert math.isnan(row["kendall_tau"]) and math.isnan(row["tau_lo"]) and len(rows) == 3
    assert row["tau_note"] == (
        "no tau: 3 methods, too few to tell agreement from chance (at least 6)"
    )
    five = pd.Series([1.0, 2, 3, 4, 5], METHODS6[:5])
    five, _ = compare(five, five, lower_better=False)
    assert math.isnan(five["kendall_tau"]) and "5 methods" in five["tau_note"]


def test_the_transfer_figures_labels_of_tied_methods_never_overlap(monkeypatch, tmp_path):
    """Methods tied on the dataset (five at one rank in kitti-seq2's sfm_maa, sees image)
    had their names drawn over each other; methods tied on both sides share one label."""
    from bench.report import figures

    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.update(fig=fig))
    tied = [("random", 13), ("grid", 11), ("quadtree", 10), ("ssc", 9), ("matchable", 8)]
    at = {m: (r, 11) for m, r in tied}  # method: (rendered rank, dataset rank)
    at |= {"texture": (12, 7), "response": (7, 8), "scale": (6, 5), "octave-scale": (5, 4)}
    at |= {"peak-scale": (4, 3), "colmap-b": (3, 2), "response@colmap-soft-b": (2, 6)}
    at |= {"colmap-soft-b": (1, 1), "x": (12, 12.5), "y": (12, 12.5)}
    key = {"dataset": "kitti-seq2", "sees": "image", "metric": "sfm_maa", "budget": 256}
    ranks = pd.DataFrame(
        [key | {"method": m, "rank_rendered": r, "rank_dataset": d} for m, (r, d) in at.items()]
    )
    summary = pd.DataFrame(
        [key | {"kendall_tau": 0.5, "tau_lo": 0.1, "tau_hi": 0.9, "tau_note": ""}]
    )
    figures.figure_transfer(ranks, summary, 256, tmp_path / "figure_transfer")
    fig = drawn["fig"]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    (ax,) = fig.axes
    labels = [t for t in ax.texts if t.get_text()]
    boxes = [t.get_window_extent(renderer) for t in labels]
    assert not [
        (a.get_text(), b.get_text())
        for k, (a, p) in enumerate(zip(labels, boxes))
        for b, q in zip(labels[k + 1 :], boxes[k + 1 :])
        if p.overlaps(q)
    ]
    assert all(ax.bbox.contains(b.x0, b.y0) and ax.bbox.contains(b.x1, b.y1) for b in boxes)
    assert sorted(t.get_text() for t in labels) == sorted([*list(at)[:-2], "x\ny"])


def test_dataset_without_pixel_truth_scores_poses_and_leaves_the_rest_nan(
    dataset, renders_dir, tmp_path, capsys
):
    bare = tmp_path / "bare"
    shutil.copytree(dataset / "images", bare / "images")
    shutil.copytree(dataset / "sparse", bare / "sparse")
    code = main(
        [
            "run",
            "--dataset",
            str(bare),
            "--methods",
            "texture,oracle",
            "--budget",
            "64",
            "--results",
            str(tmp_path / "res"),
            "--workers",
            "1",
            "--renders",
            str(renders_dir),
        ]
    )
    assert code == 0
    assert "no per-pixel ground truth: the oracle is left out" in capsys.readouterr().err
    runs = pd.read_csv(tmp_path / "res" / "runs.csv")
    assert set(runs["method"]) == {"texture"} and set(runs["scene"]) == {"bare"}
    sfm = runs[runs["task"] == "sfm"]
    assert sfm["maa"].notna().all() and runs["rmse"].isna().all()
    assert runs["acc_completeness_pct"].isna().all()


def test_select_writes_a_database_colmap_matches(dataset, tmp_path):
    request = SelectRequest(
        dataset / "images", "adaptive", 150, cameras=dataset / "sparse", overlays=True
    )
    db_path = select_to_database(request, tmp_path / "out")
    db = pycolmap.Database.open(str(db_path))
    try:
        images = db.read_all_images()
        assert len(images) == 6
        for img in images:
            assert db.read_keypoints(img.image_id).shape[0] == 150
            d = db.read_descriptors(img.image_id).data
            assert d.shape == (150, 128) and d.dtype == np.uint8
    finally:
        db.close()
    opts = pycolmap.FeatureMatchingOptions()
    opts.num_threads = 1
    pycolmap.match_exhaustive(db_path, matching_options=opts, device=pycolmap.Device.cpu)
    db = pycolmap.Database.open(str(db_path))
    try:
        assert db.num_matches() > 0 and db.num_inlier_matches() > 0
    finally:
        db.close()
    assert sorted(p.name for p in (tmp_path / "out" / "overlays").iterdir()) == [
        f"view_{k:02d}.png" for k in range(6)
    ]


def test_select_says_what_it_replaces_and_what_falls_short(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    select_to_database(SelectRequest(dataset / "images", "texture", 64, overlays=True), out)
    capsys.readouterr()
    pool = 10**5  # above every pool: refused, as `bench run` refuses it
    with pytest.raises(BenchError, match="budget 100000 exceeds every candidate pool of the 6"):
        select_to_database(SelectRequest(dataset / "images", "texture", pool), out)
    select_to_database(SelectRequest(dataset / "images", "texture", 64), out)
    err = capsys.readouterr().err
    said = f"{out / 'database.db'} already existed: kept as {out / 'database.1.db'}"
    assert said in err and (out / "database.1.db").is_file()
    assert not (out / "overlays").exists()  # the earlier run's overlays do not linger
    (tmp_path / "file").write_text("x")
    argv = ["select", "--images", str(dataset / "images"), "--out", str(tmp_path / "file")]
    assert main(argv) == 2
    assert "is a file; give a folder" in capsys.readouterr().err


def test_dataset_runs_name_the_options_they_ignore_and_record_no_render(
    dataset, renders_dir, tmp_path, capsys
):
    argv = ["run", "--dataset", str(dataset), "--methods", "texture", "--budget", "64"]
    argv += ["--tasks", "tri", "--protocols", "multiview", "--workers", "1", "--width", "100"]
    argv += ["--results", str(tmp_path / "r"), "--renders", str(renders_dir)]
    assert main([*argv, "--scenes", "table"]) == 0
    err = capsys.readouterr().err
    assert "--width, --scenes ignored with --dataset" in err
    assert "render:" not in err  # was "render: 1/1 scene (100 %), 20520.82 scene/s"
    config = json.loads((tmp_path / "r" / "config.json").read_text())
    assert config["settings"]["render"] is None
    assert main([*argv, "--spp", "4"]) == 0  # other render options: named, not refused


def test_select_with_a_model_of_more_images_uses_those_present(dataset, tmp_path, capsys):
    """A model listing more images than the folder holds stopped `bench select` with
    `cannot read image .../view_04.png`."""
    folder = tmp_path / "four"
    folder.mkdir()
    for k in (0, 1, 3, 5):
        shutil.copy(dataset / "images" / f"view_{k:02d}.png", folder)
    cv2.imwrite(str(folder / "extra.png"), cv2.imread(str(folder / "view_00.png")))
    argv = ["select", "--images", str(folder), "--cameras", str(dataset / "sparse")]
    assert main([*argv, "--budget", "40", "--policy", "texture", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    said = f"the model in {dataset / 'sparse'} poses 2 image(s) besides the 4 in {folder} "
    assert said + "(first: view_02.png); using those present" in err
    assert f"{folder}: 1 image(s) the model in {dataset / 'sparse'} does not pose" in err
    truth = dict(read_model(dataset / "sparse"))
    db = pycolmap.Database.open(str(tmp_path / "o" / "database.db"))
    try:
        images = {i.name: i for i in db.read_all_images()}
        assert sorted(images) == [f"view_{k:02d}.png" for k in (0, 1, 3, 5)]
        assert db.num_keypoints() == 4 * 40
        for name, image in images.items():  # the model's intrinsics
            assert db.read_camera(image.camera_id).params[0] == pytest.approx(truth[name].fx)
    finally:
        db.close()


def test_select_with_matches_holds_verified_geometries_the_mapper_reads(dataset, tmp_path):
    request = SelectRequest(
        dataset / "images", "adaptive", 200, cameras=dataset / "sparse", match=True
    )
    db_path = select_to_database(request, tmp_path / "o")
    db = pycolmap.Database.open(str(db_path))
    try:
        pair_ids, geometries = db.read_two_view_geometries()
        assert len(pair_ids) >= 3
        for pid, tvg in zip(pair_ids, geometries):
            i, j = pycolmap.pair_id_to_image_pair(pid)
            assert tvg.inlier_matches[:, 0].max() < len(db.read_keypoints(i))
            assert tvg.inlier_matches[:, 1].max() < len(db.read_keypoints(j))
    finally:
        db.close()
    # COLMAP's mapper maps it: every view, on exactly the selected keypoints, with the
    # model's intrinsics, near the true poses (thresholds for 200 keypoints of 320x240 views)
    opts = fixed_intrinsics_options(BackendConfig(), "multiview")
    opts.min_model_size = 3
    opts.mapper.init_min_num_inliers = opts.mapper.abs_pose_min_num_inliers = 15
    opts.mapper.init_min_tri_angle = 4
    models = pycolmap.incremental_mapping(db_path, dataset / "images", tmp_path / "m", opts)
    assert len(models) == 1
    model = models[0]
    truth = dict(read_model(dataset / "sparse"))
    images = {i.name: i for i in model.images.values() if i.has_pose}
    assert sorted(images) == sorted(truth) and model.num_points3D() > 0
    assert all(len(i.points2D) == 200 for i in images.values())
    (cam,) = model.cameras.values()
    assert np.allclose(cam.params[:1], truth["view_00.png"].fx)
    first = images["view_00.png"].cam_from_world().rotation.matrix()
    for name, image in images.items():  # rotation relative to the first view, in degrees
        rel = image.cam_from_world().rotation.matrix() @ first.T
        true = truth[name].R @ truth["view_00.png"].R.T
        assert np.degrees(np.arccos(np.clip((np.trace(rel.T @ true) - 1) / 2, -1, 1))) < 8


def test_image_folders_of_several_sizes_and_a_bad_file(dataset, tmp_path, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    for k, scale in enumerate((1.0, 0.75, 1.0)):
        img = cv2.imread(str(dataset / "images" / f"view_{k:02d}.png"))
        cv2.imwrite(str(folder / f"p{k}.jpg"), cv2.resize(img, None, fx=scale, fy=scale))
    (folder / "broken.jpg").write_bytes(b"not an image")
    assert (
        main(["select", "--images", str(folder), "--budget", "40", "--out", str(tmp_path / "o")])
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "broken.jpg" in err
    (folder / "broken.jpg").unlink()
    views = load_image_folder(folder)
    assert [v.image.shape[:2] for v in views] == [(240, 320), (180, 240), (240, 320)]
    assert views[1].camera.fx == pytest.approx(1.2 * 240) and not views[0].posed
    small_pool = ["--max-candidates", "60", "--policy", "ssc"]
    assert (
        main(["select", "--images", str(folder), "--budget", "40", "--out", str(tmp_path / "o")])
        == 0
    )
    assert (
        main(
            [
                "select",
                "--images",
                str(folder),
                "--budget",
                "40",
                "--out",
                str(tmp_path / "s"),
                *small_pool,
            ]
        )
        == 0
    )
    db = pycolmap.Database.open(str(tmp_path / "o" / "database.db"))
    try:
        assert db.num_cameras() == 2 and db.num_keypoints() == 3 * 40
    finally:
        db.close()


def _copy(dataset, to, model_to="sparse"):
    """A dataset's images and text model copied (the model into `model_to`)."""
    shutil.copytree(dataset / "images", to / "images")
    shutil.copytree(dataset / "sparse", to / model_to)
    return to


def test_binary_models_in_sparse_0_read_as_their_text_model(dataset, tmp_path):
    text = load_views(dataset)
    binary = tmp_path / "bin"
    _copy(dataset, binary, "text")
    pycolmap.Reconstruction(str(binary / "text")).write_binary(str(_mkdir(binary / "sparse/0")))
    shutil.rmtree(binary / "text")
    assert sorted(p.name for p in (binary / "sparse" / "0").iterdir())[:2] == [
        "cameras.bin",
        "frames.bin",
    ]
    views = load_views(binary)
    assert [v.name for v in views] == [v.name for v in text]
    for a, b in zip(views, text):
        assert np.allclose(a.camera.K, b.camera.K, atol=1e-9)
        assert np.allclose(a.camera.R, b.camera.R, atol=1e-12)
        assert np.allclose(a.camera.t, b.camera.t, atol=1e-12)
    assert source_key(binary) != source_key(dataset)  # another model file: another key


def _mkdir(path):
    path.mkdir(parents=True)
    return path


@pytest.mark.parametrize(
    "damage, message",
    [
        ("drop_point_lines", "images.txt line 5: expected the 2D points of image view_00.png"),
        ("word_for_number", "images.txt line 4: 'abc' is not a number"),
        ("camera_params", "cameras.txt line 1: PINHOLE has 4 parameters, found 3"),
        ("truncate_binary", "images.bin record 6 of 6: truncated"),
    ],
)
def test_a_malformed_model_is_refused_in_one_line_naming_file_and_line(
    dataset, tmp_path, damage, message
):
    ds = _copy(dataset, tmp_path / "ds")
    images, cameras = ds / "sparse" / "images.txt", ds / "sparse" / "cameras.txt"
    lines = images.read_text().splitlines()
    data = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")]
    if damage == "drop_point_lines":
        images.write_text("\n".join(ln for ln in lines if ln.strip()) + "\n")
    elif damage == "word_for_number":
        first = lines[data[0]].split()
        lines[data[0]] = " ".join([first[0], "abc", *first[2:]])
        images.write_text("\n".join(lines) + "\n")
    elif damage == "camera_params":
        cameras.write_text("1 PINHOLE 320 240 300 300 160\n")
    else:
        pycolmap.Reconstruction(str(ds / "sparse")).write_binary(str(_mkdir(ds / "bin")))
        shutil.rmtree(ds / "sparse")
        (ds / "bin").rename(ds / "sparse")
        blob = (ds / "sparse" / "images.bin").read_bytes()
        (ds / "sparse" / "images.bin").write_bytes(blob[:-30])
    with pytest.raises(BenchError, match="malformed COLMAP model") as err:
        load_views(ds)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_text_model_with_points_reads(dataset, tmp_path):
    ds = _copy(dataset, tmp_path / "ds")
    (ds / "sparse" / "points3D.txt").write_text(
        "# a point with its reprojection error\n7 0.5 1.5 2.5 10 20 30 0.8731\n"
    )
    assert len(load_views(ds)) == 6


def test_the_model_poses_exactly_the_images_of_the_dataset(dataset, tmp_path):
    ds = _copy(dataset, tmp_path / "ds")
    (ds / "images" / "view_05.png").rename(ds / "view_05.png")
    with pytest.raises(BenchError, match=r"1 image\(s\) of the model .* not in .*view_05.png"):
        load_views(ds)
    (ds / "view_05.png").rename(ds / "images" / "extra.png")
    (ds / "images" / "view_05.png").symlink_to(ds / "images" / "extra.png")
    with pytest.raises(BenchError, match="does not pose .*extra.png"):
        load_views(ds)


def test_a_large_view_is_detected_downscaled_and_keeps_full_resolution_keypoints(dataset, tmp_path):
    """A dataset upscaled 2x, detected at max_image_size = the original size: its
    candidates are the original's at twice their coordinates (the resampling adds and
    moves some, but those found again sit where they should, with no half-pixel shift)."""
    big = tmp_path / "big"
    _copy(dataset, big)
    for f in (big / "images").iterdir():
        img = cv2.imread(str(f))
        cv2.imwrite(str(f), cv2.resize(img, None, fx=2, fy=2, interpolation=cv2.INTER_LINEAR))
    rec = pycolmap.Reconstruction(str(big / "sparse"))
    for cam in rec.cameras.values():
        cam.rescale(2.0)
    rec.write_text(str(big / "sparse"))
    det, sig = DetectorConfig(), SignalConfig()
    small = front_end(dataset, det, sig, tmp_path / "fe", RIG)
    large = front_end(big, replace(det, max_image_size=320), sig, tmp_path / "fe", RIG)
    assert large.views[0].image.shape[:2] == (480, 640)
    for a, b in zip(small.pools, large.pools):
        d, nn = cKDTree(a.xy * 2).query(b.xy)
        near = d < 2
        offset = (b.xy - 2 * a.xy[nn])[near].mean(0)
        assert 0.7 < len(b) / len(a) < 1.5 and np.mean(near) > 0.45
        assert np.abs(offset).max() < 0.1 and np.median(d[near]) < 0.3
        assert b.xy.max(0)[0] <= 640 and b.xy.max(0)[1] <= 480
        assert np.median(b.size) == pytest.approx(2 * np.median(a.size), rel=0.2)


def test_max_features_keeps_the_strongest_candidates(dataset):
    view = load_views(dataset)[0]
    every = detect(view, DetectorConfig())
    some = detect(view, DetectorConfig(max_features=50))
    assert len(some) == 50 and len(every) > 50
    assert np.sort(some.response)[0] >= np.sort(every.response)[-50]


def test_distorted_camera_models_are_refused_in_one_line(tmp_path):
    (tmp_path / "cameras.txt").write_text("1 OPENCV 640 480 500 500 320 240 0.1 0 0 0\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    with pytest.raises(BenchError, match="distortion is not supported; undistort"):
        read_model(tmp_path)


def test_a_dataset_whose_contents_changed_is_computed_again(
    medium_entry, renders_dir, tmp_path, capsys
):
    """A dataset is keyed by its content: a facade export replacing a table export in the
    same folder is computed again (the table's rows were reused: "0 to compute")."""
    ds = tmp_path / "D"
    export_dataset(medium_entry("table"), ds)
    argv = ["run", "--dataset", str(ds), "--methods", "texture", "--budget", "64", "--tasks"]
    argv += ["tri", "--protocols", "multiview", "--workers", "1", "--results", str(tmp_path / "r")]
    argv += ["--renders", str(renders_dir)]
    assert main(argv) == 0
    first = pd.read_csv(tmp_path / "r" / "runs.csv")
    export_dataset(medium_entry("facade"), ds)
    assert f"replacing the export of table seed 0 in {ds}" in capsys.readouterr().err
    assert main(argv) == 0
    assert "changed since 1 row(s) were computed; computing them again" in capsys.readouterr().err
    again = pd.read_csv(tmp_path / "r" / "runs.csv")
    assert len(again) == 1 and again["render_key"][0] != first["render_key"][0]
    assert again["reconstructable"][0] != first["reconstructable"][0]


def test_several_datasets_run_at_once_with_tables_per_dataset_and_a_transfer_table(
    medium_entry, quick_results, renders_dir, tmp_path, capsys
):
    sets = tmp_path / "sets"
    export_dataset(medium_entry("table"), sets / "table-ds")
    export_dataset(medium_entry("facade"), sets / "facade-ds")
    policies = ["random", "texture", "grid", "adaptive"]
    grid = ["--methods", ",".join(policies), "--budget", "64", "--tasks", "tri"]
    grid += ["--protocols", "multiview", "--workers", "1", "--renders", str(renders_dir)]

    def rendered(rows):  # table seed 0 at MEDIUM: the small grid's rows of these units
        units = (rows["scene"] == "table") & rows["method"].isin(policies)
        return units & (rows["task"] == "tri") & (rows["protocol"] == "multiview")

    assert len(read_runs(rows_of(quick_results, tmp_path / "r", rendered) / "runs.csv")) == 4
    argv = ["run", "--dataset", str(sets), *grid, "--results", str(tmp_path / "d")]
    capsys.readouterr()
    assert main([*argv, "--rendered", str(tmp_path / "r")]) == 0
    out = tmp_path / "d"
    err = capsys.readouterr().err  # the terminal names transfer.csv and why it has no tau
    for name in ("table-ds", "facade-ds"):
        line = f"{out / 'transfer.csv'}: {name} against the 6-view regime at B = 64, Kendall's "
        assert line + "tau: no tau: 3 methods, too few to tell agreement" in err
    assert set(pd.read_csv(out / "runs.csv")["scene"]) == {"table-ds", "facade-ds"}
    for name in ("table-ds", "facade-ds"):
        assert set(pd.read_csv(out / f"table1-{name}.csv")["method"]) == {
            "random",
            "texture",
            "grid",
            "adaptive",
        }
    summary, ranks = pd.read_csv(out / "transfer.csv"), pd.read_csv(out / "transfer_ranks.csv")
    assert set(summary["dataset"]) == {"table-ds", "facade-ds"}
    assert set(summary["metric"]) == {"acc_completeness_pct"} and (summary["methods"] == 3).all()
    assert summary["kendall_tau"].isna().all() and summary["tau_note"].str.contains("3 meth").all()
    assert (ranks.loc[ranks["dataset"] == "table-ds", "rank_shift"] == 0).all()
    assert (out / "figure_transfer.png").is_file()


def test_each_dataset_is_matched_with_the_regime_nearest_its_view_count(monkeypatch):
    """Against a 6-view and a 21-view rendered folder, an 8-view set is matched with the
    sparse regime and a 16-view set with the dense one; ties go to the denser."""
    from bench.report import transfer as module

    def one(rows, vocab, rendered):
        views = int(rendered.name)
        summary = pd.DataFrame({"dataset": ["a", "b", "c"], "rendered_views": views})
        return summary, summary.assign(method="texture")

    monkeypatch.setattr(module, "transfer", one)
    rows = pd.DataFrame({"scene": ["a", "b", "c"], "views": [8, 16, 27]})
    summary, ranks = module.transfer_regimes(rows, None, [Path("6"), Path("21")])
    matched = summary[summary["matched"]].set_index("dataset")["rendered_views"]
    assert matched.to_dict() == {"a": 6, "b": 21, "c": 21}
    assert ranks["matched"].tolist() == summary["matched"].tolist()
    rows["views"] = [13.5, 13.5, 13.5]  # equidistant from 6 and 21
    summary, _ = module.transfer_regimes(rows, None, [Path("6"), Path("21")])
    assert set(summary.loc[summary["matched"], "rendered_views"]) == {21}


def test_the_biggest_movers_name_which_rank_is_which():
    """It read "texture 6 -> 3", saying nothing of which rank is the renders'."""
    from bench.report.transfer import compare

    three = list("abc")
    row, _ = compare(pd.Series([1.0, 2, 3], three), pd.Series([3.0, 2, 1], three), False)
    assert row["biggest_movers"] == "a rendered 1 -> set 3; c rendered 3 -> set 1"


# --- the formats of a dataset's model (bench.frontend.formats) -----------------------


def _tiny_dataset(folder: Path, model: str = "sparse") -> list[Camera]:
    """Three 64x48 noise images in `images/` and their COLMAP text model in `model`."""
    cams = [look_at((x, -6.0, 1.0), (0.0, 0.0, 1.0), width=64, height=48) for x in (-1, 0, 1)]
    (folder / "images").mkdir(parents=True)
    rng = np.random.default_rng(0)
    for k in range(3):
        cv2.imwrite(
            str(folder / "images" / f"v{k}.png"), rng.integers(0, 255, (48, 64, 3), np.uint8)
        )
    _mkdir(folder / model)
    write_colmap_rig(cams, folder / model, [f"v{k}.png" for k in range(3)])
    return cams


def test_the_colmap_models_are_the_first_two_formats_of_the_registry(tmp_path):
    assert list(formats.FORMATS)[:2] == ["colmap-binary", "colmap-text"]
    cams = _tiny_dataset(tmp_path / "text")
    _tiny_dataset(tmp_path / "bin", "text")
    rec = read_reconstruction(tmp_path / "bin" / "text")
    rec.write_binary(str(_mkdir(tmp_path / "bin" / "sparse" / "0")))
    shutil.rmtree(tmp_path / "bin" / "text")
    for name, kind in (("text", "colmap-text"), ("bin", "colmap-binary")):
        src = Source.of(tmp_path / name)
        assert src.format.name == kind and src.images == tmp_path / name / "images"
        views = load_views(src)
        assert [v.name for v in views] == ["v0.png", "v1.png", "v2.png"]
        for v, c in zip(views, cams):
            assert np.allclose(v.camera.K, c.K) and np.allclose(v.camera.t, c.t)


@pytest.fixture
def registry(monkeypatch):
    """The registry of formats, as it is, for a test to add to (restored after it)."""
    monkeypatch.setattr(formats, "FORMATS", dict(formats.FORMATS))
    return formats.FORMATS


def test_a_format_registered_elsewhere_is_read_by_source_and_load_views(tmp_path, registry):
    """A format of one's own (here a JSON file of cameras beside `images/`) is one decorated
    reader: `Source.of` and `load_views` read it, and its file is part of the key."""

    def read_json(folder: Path) -> list[tuple[str, Camera]]:
        cams = json.loads((folder / "rig.json").read_text())
        return sorted(
            (name, Camera(c["w"], c["h"], *c["k"], np.array(c["R"]), np.array(c["t"])))
            for name, c in cams.items()
        )

    formats.dataset_format(
        "rig-json", lambda f: (f / "rig.json").is_file(), "a rig.json", places=(".",)
    )(read_json)
    cams = _tiny_dataset(tmp_path / "ds")
    shutil.rmtree(tmp_path / "ds" / "sparse")
    rig = {
        f"v{k}.png": {
            "w": 64,
            "h": 48,
            "k": [c.fx, c.fy, c.cx, c.cy],
            "R": c.R.tolist(),
            "t": c.t.tolist(),
        }
        for k, c in enumerate(cams)
    }
    (tmp_path / "ds" / "rig.json").write_text(json.dumps(rig))
    src = Source.of(tmp_path / "ds")
    assert src.format.name == "rig-json" and src.seen() == {}
    views = load_views(tmp_path / "ds")
    assert [v.name for v in views] == ["v0.png", "v1.png", "v2.png"]
    assert all(np.allclose(v.camera.R, c.R) for v, c in zip(views, cams))
    assert views[2].image.shape == (48, 64, 3)
    key = source_key(tmp_path / "ds")
    rig["v0.png"]["k"][0] += 1
    (tmp_path / "ds" / "rig.json").write_text(json.dumps(rig))
    assert source_key(tmp_path / "ds") != key


def test_a_folder_of_no_known_format_is_one_line_naming_each_format(tmp_path, registry):
    is_rig = lambda f: (f / "rig.json").is_file()  # noqa: E731
    formats.dataset_format("rig-json", is_rig, "a rig.json")(lambda folder: [])
    _tiny_dataset(tmp_path / "ds")
    (tmp_path / "ds" / "sparse" / "images.txt").unlink()  # cameras alone are no model
    with pytest.raises(BenchError) as err:
        Source.of(tmp_path / "ds")
    said = str(err.value)
    assert "\n" not in said and said.startswith(f"{tmp_path / 'ds'} is neither a render entry")
    for what in ("COLMAP binary model (cameras.bin, images.bin)", "a rig.json in sparse/0/"):
        assert what in said
    with pytest.raises(BenchError, match="holds no model"):
        load_image_folder(tmp_path / "ds" / "images", tmp_path / "ds" / "sparse")
