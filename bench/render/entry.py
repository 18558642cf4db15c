"""Render entries: a scene and seed to a cached `renders/` entry (its views, their ground
truth, the rig), rendered through `bench.render.mitsuba` only when missing or damaged.

Each view is cached on its own too (`renders/views/`, keyed by its position on the scene's
path: `view_key`), and an entry links its views from there: a rig of 21 views on a path
renders only the 15 views a rig of 6 on the same path does not have, and the other way round.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
from collections.abc import Callable, Iterator
from fractions import Fraction
from importlib.metadata import version
from pathlib import Path

import cv2
import numpy as np

from bench import BenchError, files
from bench.camera import write_colmap_rig
from bench.codehash import code_hash
from bench.console import log
from bench.render import reference
from bench.render.config import RenderConfig
from bench.render.mitsuba import AOVS, GT_LAYERS, MITSUBA_FROM_OPENCV, render_view, truth_view
from bench.render.variant import resolve_variant
from bench.scenes.catalog import (
    build_scene,
    load_spec,
    path_positions,
)
from bench.scenes.spec import SceneSpec

RENDER_CODE = ("bench.render.mitsuba", "bench.camera")
"""Where the code that decides a render entry's content starts (the scenes, their
generators, the path tracer, the developing step, the rig): its import closure
(`bench.codehash.code_hash`); this module's cache plumbing is not in it, so editing it
re-renders nothing."""


def _pixel_fields(spec: SceneSpec, seed: int, cfg: RenderConfig, variant: str) -> dict:
    """Everything that changes a view's pixels but its place on the path."""
    return {
        "scene": spec.name,
        "params": spec.params,
        "seed": seed,
        "width": cfg.width,
        "height": cfg.height,
        "spp": cfg.spp,
        "max_depth": cfg.max_depth,
        "denoise": cfg.denoise,
        "variant": variant,
        "code": code_hash(RENDER_CODE),
        "aovs": AOVS,
        "mitsuba_from_opencv": MITSUBA_FROM_OPENCV.tolist(),
        "mitsuba": version("mitsuba"),
        "drjit": version("drjit"),
    }


def render_key(spec: SceneSpec, seed: int, cfg: RenderConfig, variant: str) -> str:
    """Hash of everything that changes pixels: scene, seed, rig, settings, code
    (`RENDER_CODE`), renderer."""
    return files.content_key({**_pixel_fields(spec, seed, cfg, variant), "views": cfg.views})


def view_key(spec: SceneSpec, seed: int, cfg: RenderConfig, variant: str, u: Fraction) -> str:
    """Hash of one view: `render_key`'s fields with its position on the path for the view
    count (the scene's cameras and motion are functions of it), so that rigs of different
    view counts share the views they have in common."""
    where = f"{u.numerator}/{u.denominator}"
    return files.content_key({**_pixel_fields(spec, seed, cfg, variant), "path_position": where})


_announced: set[str] = set()


def load_renderer(variant: str) -> None:
    """Load Mitsuba and its variant before any lock or temporary folder exists: a signal
    that lands while its native libraries initialise aborts the process, and then leaves
    nothing behind."""
    import mitsuba

    mitsuba.set_variant(variant)


def render_view_entry(
    desc, v: int, cfg: RenderConfig, variant: str, entry: Path, force: bool
) -> dict:
    """The cache entry of one view (`view_key`): its image and ground truth, rendered only
    if missing, damaged or forced; its meta."""
    with files.locked(entry):
        if entry.exists() and not force and files.entry_problem(entry) is None:
            return files.read_meta(entry)
        with files.atomic_dir(entry) as tmp:
            t0 = time.perf_counter()
            image, gt, names = render_view(desc, v, cfg, variant)
            cv2.imwrite(str(tmp / "view.png"), image[..., ::-1])
            np.savez(tmp / "gt.npz", **gt)
            meta = {"seconds": time.perf_counter() - t0, "shape_names": names}
            files.write_meta(tmp, meta)
        log(
            f"rendered {desc.name} seed {desc.seed} view {v + 1}/{cfg.views} in "
            f"{meta['seconds']:.1f} s ({variant})"
        )
        return meta


def _link(src: Path, dst: Path) -> None:
    """A hard link where the file system allows one, else a copy."""
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _resolved(
    name: str, seed: int, cfg: RenderConfig, renders_dir: Path
) -> tuple[SceneSpec, str, str, dict | None]:
    """The scene's spec, the variant this machine renders (or recomputes truth) with, the
    path of its cache entry under `renders_dir`, and the reference set's record of the rig
    when the entry is made from it (`bench.render.reference`: the set holds the rig under
    the render key of these settings and code, and no variant was asked for by name)."""
    cfg.validate()
    if not isinstance(seed, int) or seed < 0:
        raise BenchError(f"seed must be a non-negative integer, got {seed!r}")
    spec = load_spec(name)  # an unknown scene is one line, before the variant's
    variant, why = resolve_variant(cfg.variant, Path(renders_dir))
    if why not in _announced:  # once per process (the calling one: `render_scenes`)
        _announced.add(why)
        log(why)
    made_with = reference.reference_variant()
    if made_with is not None:
        key = render_key(spec, seed, cfg, made_with)
        rig = reference.reference_rig(name, seed, cfg, key)
        if rig is not None:
            return spec, variant, f"{reference.SUBFOLDER}/{name}-s{seed}-{key}", rig
    return spec, variant, f"{name}-s{seed}-{render_key(spec, seed, cfg, variant)}", None


def entry_names(name: str, seed: int, cfg: RenderConfig, renders_dir: Path) -> list[str]:
    """The name a current cache entry of (scene, seed, settings) has (what a row records
    as its `render_key`; its `pixels` say which images it read)."""
    return [Path(_resolved(name, seed, cfg, renders_dir)[2]).name]


def entry_meta(entry: Path) -> dict:
    """What a render entry records of itself (`render_scene`): scene, seed, settings,
    variant, versions, seconds per view, shape names, the cameras, its `pixels` (and where
    it came from the reference set, that and how its truth was made): the one reader of a
    render entry's record."""
    return files.read_meta(entry)


def image_name(view: int) -> str:
    """The file name of a render entry's view `view` (its COLMAP model names it so)."""
    return f"view_{view:02d}.png"


def truth_name(view: int) -> str:
    """The file name of a render entry's ground-truth layers of view `view`."""
    return f"gt_{view:02d}.npz"


def entry_name(name: str, seed: int, cfg: RenderConfig, renders_dir: Path) -> str:
    """The path, under `renders_dir`, of the cache entry of (scene, seed, settings), without
    making it: `reference/<name>` for a rig of the reference set."""
    return _resolved(name, seed, cfg, renders_dir)[2]


def cached_entry(name: str, seed: int, cfg: RenderConfig, renders_dir: Path) -> Path | None:
    """The whole cache entry of (scene, seed, settings) where one is made (every file's
    checksum verified), None where not; a copy of the reference set's has its shipped
    source checked too (`bench.render.reference.checked_files`)."""
    _, _, entry, rig = _resolved(name, seed, cfg, renders_dir)
    entry = Path(renders_dir) / entry
    if not entry.is_dir() or files.entry_problem(entry) is not None:
        return None
    if rig is not None:
        reference.checked_files(rig)
    return entry


def known_pixels(name: str, seed: int, cfg: RenderConfig, renders_dir: Path) -> str | None:
    """The `pixels` the entry of (scene, seed, settings) has, where known without making
    it: the reference set's, or those of an entry already made here (None otherwise)."""
    _, _, entry, rig = _resolved(name, seed, cfg, renders_dir)
    if rig is not None:
        return rig["pixels"]
    entry = Path(renders_dir) / entry
    if entry.is_dir() and files.entry_problem(entry) is None:
        return files.read_meta(entry).get("pixels") or _pixels(entry, cfg.views)
    return None


def _pixels(entry: Path, views: int) -> str:
    """The `pixels` of an entry's views (`bench.files.views_pixels`)."""
    return files.views_pixels([entry / image_name(v) for v in range(views)])


def render_scene(
    name: str, seed: int, cfg: RenderConfig, renders_dir: Path, force: bool = False
) -> Path:
    """The cache entry of (scene, seed, settings): made from the reference set where it
    holds the rig, else rendered; only if missing or damaged (every file's size and
    checksum are verified on a hit)."""
    renders_dir = Path(renders_dir)
    spec, variant, entry, rig = _resolved(name, seed, cfg, renders_dir)
    entry = renders_dir / entry
    if force or not entry.exists() or files.entry_problem(entry):
        load_renderer(variant)
    with files.locked(entry):
        problem = files.entry_problem(entry) if entry.exists() else None
        if entry.exists() and problem is None and not force:
            if rig is not None:  # the cached copy of the shipped data: its source still sound
                reference.checked_files(rig)
            return entry
        if problem:
            log(f"damaged cache entry {entry.name} ({problem}); making it again")
        if rig is not None:
            _from_reference(spec, seed, cfg, variant, rig, entry)
            return entry
        desc = build_scene(spec, seed, cfg.width, cfg.height, cfg.views)
        with files.atomic_dir(entry) as tmp:
            seconds, names = [], None
            for v, u in enumerate(path_positions(cfg.views)):
                _stop_point()
                view = (
                    renders_dir
                    / "views"
                    / f"{name}-s{seed}-{view_key(spec, seed, cfg, variant, u)}"
                )
                meta = render_view_entry(desc, v, cfg, variant, view, force)
                _link(view / "view.png", tmp / image_name(v))
                _link(view / "gt.npz", tmp / truth_name(v))
                seconds.append(meta["seconds"])
                names = meta["shape_names"]
            write_colmap_rig(desc.cameras, tmp, [image_name(v) for v in range(cfg.views)])
            meta = _meta(spec, seed, cfg, desc.cameras, names, seconds)
            files.write_meta(tmp, meta | {"pixels": _pixels(tmp, cfg.views), "variant": variant})
    return entry


def _meta(spec: SceneSpec, seed: int, cfg: RenderConfig, cameras, names, seconds) -> dict:
    """What an entry records of itself (`entry_meta`), but its variant and pixels."""
    return {
        "scene": spec.name,
        "seed": seed,
        "params": spec.params,
        **{k: getattr(cfg, k) for k in ("views", "width", "height", "spp", "max_depth")},
        "denoise": cfg.denoise,
        "versions": {"mitsuba": version("mitsuba"), "drjit": version("drjit")},
        "seconds_per_view": seconds,
        "shape_names": names,
        "gt_layers": {
            k: "float32; NaN (shape_index -1) where the pixel saw nothing" for k in GT_LAYERS
        },
        "cameras": [
            {"K": c.K.tolist(), "R_cam_from_world": c.R.tolist(), "t": c.t.tolist()}
            for c in cameras
        ],
    }


def _from_reference(
    spec: SceneSpec, seed: int, cfg: RenderConfig, variant: str, rig: dict, entry: Path
) -> None:
    """A render entry from the reference set (`bench.render.reference`): its shipped views
    (checked against the manifest), ground truth recomputed by the AOV pass with this
    machine's `variant` (`truth_view`), the rig, and a meta naming where it came from."""
    images = reference.checked_images(rig)
    made_by = reference.read_manifest()["made_by"]
    desc = build_scene(spec, seed, cfg.width, cfg.height, cfg.views)
    with files.atomic_dir(entry) as tmp:
        seconds, names = [], None
        for v, image in enumerate(images):
            _stop_point()
            t0 = time.perf_counter()
            gt, names = truth_view(desc, v, cfg, variant)
            cv2.imwrite(str(tmp / image_name(v)), image)
            np.savez(tmp / truth_name(v), **gt)
            seconds.append(time.perf_counter() - t0)
        write_colmap_rig(desc.cameras, tmp, [image_name(v) for v in range(cfg.views)])
        meta = _meta(spec, seed, cfg, desc.cameras, names, rig["seconds_per_view"])
        files.write_meta(
            tmp,
            meta
            | {k: made_by[k] for k in ("variant", "versions")}
            | {
                "pixels": rig["pixels"],
                "reference": {"rig": reference.rig_name(spec.name, seed, cfg.views)},
                "made_by": made_by,
                "truth": {"variant": variant, "seconds_per_view": seconds},
            },
        )
    log(f"{entry.name}: views from the reference set, truth recomputed in {sum(seconds):.0f} s")


def reference_input(entry: Path) -> dict:
    """A rendered entry as `bench.render.reference.write_reference` takes it: its views,
    what made them, and its render key under today's code."""
    meta = entry_meta(entry)
    settings = {k: meta[k] for k in ("width", "height", "spp", "max_depth", "denoise")}
    spec, cfg = load_spec(meta["scene"]), RenderConfig(views=meta["views"], **settings)
    return {
        "scene": meta["scene"],
        "seed": meta["seed"],
        "views": meta["views"],
        "render_key": render_key(spec, meta["seed"], cfg, meta["variant"]),
        "images": [cv2.imread(str(entry / image_name(v))) for v in range(meta["views"])],
        "made_by": {
            "renderer": "mitsuba {mitsuba}, drjit {drjit}".format(**meta["versions"]),
            "variant": meta["variant"],
            "versions": meta["versions"],
            "settings": settings,
        },
        "seconds_per_view": meta["seconds_per_view"],
    }


Scene = tuple[str, int]  # a scene and seed


_state = {"busy": False, "stop": False}  # a rendering process's: rendering, told to stop


def _timed(render: Callable[[str, int], Path], scene: Scene) -> tuple[Scene, Path, float]:
    t = time.perf_counter()
    _state["busy"] = True
    try:
        return scene, render(*scene), time.perf_counter() - t
    finally:
        _state["busy"] = False


def _stop(signum, frame):
    """SIGTERM in a rendering process: it leaves at once when idle; while it renders, it
    finishes the view under way and leaves before the next (`_stop_point`), since an
    exception raised inside Mitsuba's call leaves its state broken and the process hung."""
    if not _state["busy"]:
        raise SystemExit(128 + signum)
    _state["stop"] = True


def _stop_point() -> None:
    """Where a rendering process told to stop leaves: between views, its locks and
    temporary folders removed on the way out."""
    if _state["stop"]:
        raise SystemExit(128 + signal.SIGTERM)


def _render_process(told: set[str]) -> None:
    """A rendering process's start: it leaves the calling process's group, so that a
    signal to the group (Ctrl-C from a terminal, `timeout`, systemd) reaches the calling
    process alone, which stops this one with SIGTERM (`_stop`; Mitsuba catches Ctrl-C
    while it renders and returns the image cut short); it replaces glog's SIGTERM handler,
    which pycolmap's import installs (it prints the native stack); and it does not
    announce again the variant the calling process `told`."""
    os.setpgrp()
    try:
        import pycolmap  # noqa: F401
    except ImportError:
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop)
    _announced.update(told)


def render_scenes(
    scenes: list[Scene], render: Callable[[str, int], Path], processes: int
) -> Iterator[tuple[Scene, Path, float]]:
    """(scene, its entry, seconds) for each scene as its entry is ready (`render`:
        `render_scene` with its settings bound, picklable), `processes` scenes at a time, side
        by side, each in a process of its own (Mitsuba holds one scene per process; threads
        rendering at once break it): while one path-traces a view (the LLVM variant on every
        core, or the GPU, which takes several processes' views at once), another develops,
        checks and writes its own (`bench.render.develop`, ground truth, files). What a view
        holds does not depend on the order: its noise is seeded by its place on the path
        (`bench.render.mitsuba.noise_seed`) and every cache entry is written under its own
        lock, so the entries are the same files. The variant a process announces
    (`_announced`) is not announced again by the rendering processes. One process renders
    in this one, as before.
        On an interrupt, or an error, the rendering processes are stopped at once
        (`_stop_workers`): an entry, and each view's, is complete or absent
        (`bench.files.atomic_dir`)."""
    if processes <= 1 or len(scenes) <= 1:
        yield from (_timed(render, s) for s in scenes)
        return
    import multiprocessing
    from multiprocessing.connection import wait

    spawn = multiprocessing.get_context("spawn")  # no copy of this process's state
    workers = []  # each with a pipe of its own: no lock shared with a process that may die
    for _ in range(min(processes, len(scenes))):
        here, there = spawn.Pipe()
        worker = spawn.Process(target=_render_worker, args=(there, render, set(_announced)))
        worker.start()
        there.close()
        workers.append((worker, here))
    todo, busy, done = list(scenes), {}, False
    try:
        for worker, conn in workers:  # as many as there are scenes
            conn.send(todo.pop(0))
            busy[conn] = worker
        while busy:
            for conn in wait(list(busy)):
                worker = busy.pop(conn)
                try:
                    ok, value = conn.recv()
                except EOFError:
                    worker.join()
                    code = worker.exitcode
                    raise BenchError(f"a rendering process died (exit code {code})") from None
                if not ok:
                    raise value
                if todo:
                    conn.send(todo.pop(0))
                    busy[conn] = worker
                yield value
        done = True
    finally:
        _stop_workers(workers, at_once=not done)


STOP_S = 8.0
"""How long a rendering process told to stop may take to finish the view under way
(`_stop`) before it is killed: a 640x480 view takes 5-9 s on 2 cores."""


def _render_worker(conn, render: Callable[[str, int], Path], told: set[str]) -> None:
    """A rendering process: (scene, seed) pairs from `conn`, each rendered (`_timed`) and
    its result or error sent back, until None."""
    _render_process(told)
    try:
        while (scene := conn.recv()) is not None:
            try:
                result = (True, _timed(render, scene))
            except Exception as e:  # the caller raises it
                result = (False, e)
            conn.send(result)
    except EOFError:  # the calling process is gone
        pass


def _stop_workers(workers: list, at_once: bool) -> None:
    """End the rendering processes: each is told there is nothing more; `at_once` (an
    interrupt, an error) also SIGTERM, so that one rendering finishes its view and leaves
    (`_stop`), killed after `STOP_S`. Nothing here waits on a lock a process may hold."""
    for worker, conn in workers:
        try:
            conn.send(None)
        except OSError:  # it is gone
            pass
        if at_once and worker.is_alive():
            worker.terminate()
    deadline = time.monotonic() + STOP_S
    for worker, conn in workers:
        worker.join(max(0.0, deadline - time.monotonic()))
        if worker.is_alive():
            worker.kill()
            worker.join()
        conn.close()
