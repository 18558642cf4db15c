"""Shared fixtures: tiny real renders (real Mitsuba path tracing, few pixels and samples)."""

from __future__ import annotations

import signal
from pathlib import Path

import cv2
import numpy as np
import pytest

import bench.unit.declared  # noqa: F401 (every method, task and metric, as each entry point has them)
from bench.camera import Camera, look_at
from bench.frontend.colmap_model import read_model
from bench.render.config import RenderConfig

TINY = RenderConfig(width=96, height=72, spp=16, max_depth=2)


@pytest.fixture(scope="session")
def renders_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("renders")


@pytest.fixture(scope="session")
def tiny_entry(renders_dir):
    """Render (once per session) a tiny entry of a scene and seed; returns its directory."""
    from bench.render.entry import render_scene

    made: dict[tuple[str, int], Path] = {}

    def get(scene: str, seed: int = 0) -> Path:
        if (scene, seed) not in made:
            made[scene, seed] = render_scene(scene, seed, TINY, renders_dir)
        return made[scene, seed]

    return get


MEDIUM = RenderConfig(width=320, height=240, spp=16, max_depth=2)
"""Big enough for SIFT to find a few hundred candidates per view."""


@pytest.fixture(scope="session")
def frontend_cache(renders_dir) -> Path:
    """The session's front-end cache, where `bench run` keeps it (`renders/frontend`): a
    front end (candidates and signals of an entry, keyed by their settings and code) is
    computed once a session, whichever test or grid asks for it first."""
    return renders_dir / "frontend"


@pytest.fixture(scope="session")
def medium_entry(renders_dir):
    from bench.render.entry import render_scene

    made: dict[str, Path] = {}

    def get(scene: str) -> Path:
        if scene not in made:
            made[scene] = render_scene(scene, 0, MEDIUM, renders_dir)
        return made[scene]

    return get


def default_sigint() -> None:
    """A child's Ctrl-C back to its default action (`preexec_fn`): a suite started in the
    background by a non-interactive shell has SIGINT ignored, and a child inherits that."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def rig(entry: Path) -> list[Camera]:
    """A render entry's cameras in view order, read back by the library's COLMAP reader."""
    return [cam for _, cam in read_model(entry)]


def synthetic_rig():
    """Four cameras in a row looking at 150 random points in front of them."""
    cams = [
        look_at((x, -8.0, 1.0), (0.0, 0.0, 1.0), width=640, height=480)
        for x in (-1.5, -0.5, 0.5, 1.5)
    ]
    rng = np.random.default_rng(3)
    X = np.c_[rng.uniform(-2.5, 2.5, 150), rng.uniform(-1.5, 1.5, 150), rng.uniform(0, 2, 150)]
    return cams, X


def bench_run(cfg, results, renders, workers=1, scheduler=None, **options):
    """`bench run` of a grid (`BenchConfig`) with its report, as the command line runs it."""
    from bench.harness.execute import Cluster
    from bench.harness.grid import RunOptions, run_benchmark
    from bench.report.write import write_report
    from bench.results import Workspace

    options = RunOptions(cluster=Cluster(workers, scheduler), **options)
    return run_benchmark(cfg, Workspace(results, renders), options, report=write_report)


# --- a small grid of every task, shared by the harness tests -------------------------


def spy(monkeypatch, calls: list, what=lambda unit: (unit.method, unit.budget)):
    """Record `what` of every unit that is predicted (selected, matched, mapped)."""
    from bench.harness import execute

    real = execute.predict
    monkeypatch.setattr(
        execute,
        "predict",
        lambda scene, unit, *a: calls.append(what(unit)) or real(scene, unit, *a),
    )


def small_grid():
    """Two scenes, one seed, the paper's four policies, the references and two peers."""
    from bench.harness.grid import BenchConfig
    from bench.unit.config import RunConfig

    return BenchConfig(
        scenes=("table", "facade"),
        seeds=(0,),
        methods=("random", "texture", "grid", "adaptive", "all", "oracle", "colmap", "colmap-b"),
        budgets=(64,),
        run=RunConfig(render=MEDIUM),
    )


TIMING = [
    "render_s_per_view",
    "detect_ms",
    "signals_ms",
    "select_ms",
    "match_ms",
    "verify_ms",
    "task_ms",
    "evaluate_matches_ms",
    "evaluate_ms",
    "wall_ms",
    "invocation",
    "row_checksum",
]
POLICIES = ["random", "texture", "grid", "adaptive", "oracle", "colmap-b", "all", "colmap"]
ROWS = 2 * (6 * (2 * 2 + 1) + 2 * (2 + 1))
"""Scenes x (selections x (tri, sfm x protocols + pairs once) + peers x (sfm x protocols +
pairs once))."""


@pytest.fixture(scope="session")
def quick_results(renders_dir, tmp_path_factory):
    """The small grid run once for the session, as `bench run` runs it (read-only: a test
    that writes copies it)."""
    results = tmp_path_factory.mktemp("results")
    bench_run(small_grid(), results, renders_dir)
    return results


def rows_of(results: Path, folder: Path, keep) -> Path:
    """`folder`: a results folder of the rows of `results` where `keep(rows)` holds (whole
    rows, so their checksums hold) with its vocabulary and settings; a part of a grid run
    for the session, for what reads a results folder, without running that part again."""
    import shutil

    import pandas as pd

    folder.mkdir(parents=True)
    for name in ("vocabulary.json", "config.json"):
        shutil.copy(results / name, folder / name)
    rows = pd.read_csv(results / "runs.csv", dtype=str, keep_default_na=False)
    rows[keep(rows)].to_csv(folder / "runs.csv", index=False)
    return folder


def snapshot_of(results: Path, folder: Path) -> Path:
    """`folder`: a copy of `results` published as a snapshot, with its origin (computed by
    this checkout's files, every row checked against them)."""
    import shutil

    from bench.cli.common import folder_origin
    from bench.harness.origin import write_origin

    shutil.copytree(results, folder)
    write_origin(folder, folder_origin(folder, "test", Path.read_text))
    return folder


def blobs(seed: int) -> np.ndarray:
    """A 160 x 120 RGB image of blobs at two scales."""
    rng = np.random.default_rng(seed)
    img = sum(
        cv2.resize(rng.random((120 // k, 160 // k, 3)), (160, 120), interpolation=cv2.INTER_CUBIC)
        for k in (4, 12)
    )
    return np.clip(255 * (img - img.min()) / np.ptp(img), 0, 255).astype(np.uint8)
