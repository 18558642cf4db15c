"""`bench select`: the front end in front of classical SfM, on the user's own photographs.

images (+ optional COLMAP model) -> the front-end stage of `bench run`
(`bench.frontend.stage.compute`: large images downscaled to `detector.max_image_size`,
the `detector.max_features` strongest candidates, the focal length estimated where it is
guessed, the signals the policy declares) -> B per image by a policy -> OUT/database.db
(cameras, images, selected keypoints, COLMAP-format SIFT descriptors; with `match`, also
matches and verified two-view geometries) and, with `overlays`, OUT/overlays/<image>.png.
A focal length that is not known (no EXIF, no model) is written as COLMAP writes a
guess: a prior it does not trust (`has_prior_focal_length` 0), so its mapper refines it.
The database is written under a temporary name, then renamed; a database already in OUT is
kept as OUT/database.<n>.db (the first free n), and the line says so.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pycolmap

from bench import BenchError
from bench.backend.database import camera_ids
from bench.backend.reconstruction import write_database
from bench.console import log
from bench.files import atomic_path
from bench.frontend import plugins
from bench.frontend.selection import check_budgets
from bench.frontend.stage import compute
from bench.frontend.views import View, load_image_folder
from bench.unit import select_match
from bench.unit.config import RunConfig
from bench.unit.methods import runner
from bench.vocabulary import METHODS, Unit


@dataclass(frozen=True)
class SelectRequest:
    """What `bench select` is asked for."""

    images: Path
    policy: str
    budget: int
    cameras: Path | None = None
    """A COLMAP model with the intrinsics and poses (None: the focal-length prior)."""
    match: bool = False
    overlays: bool = False
    settings: RunConfig = field(default_factory=lambda: RunConfig(render=None))
    """The detector, signal, policy and back-end settings, as `bench run` has them."""


def _checked(request: SelectRequest, out: Path):
    """The request's settings, checked before any work: a folder to write, SIFT's pool
    (COLMAP's matchers read its descriptors), a method `bench select` can run."""
    if out.exists() and not out.is_dir():
        raise BenchError(f"--out {out} is a file; give a folder for database.db")
    cfg = request.settings.validate()
    if cfg.detector.detector != "sift":
        raise BenchError(
            "bench select writes COLMAP's SIFT descriptors, which COLMAP's matchers read: "
            f"detector.detector must be sift, not {cfg.detector.detector}"
        )
    plugins.load(cfg.policy.modules)
    valid = [m for m in METHODS if runner(m).photos]
    if request.policy not in valid:
        what = "a method bench select cannot run" if request.policy in METHODS else "unknown"
        raise BenchError(f"--policy {request.policy!r} is {what}; valid: {', '.join(valid)}")
    return cfg


def _written(out: Path, views, pools, sel, pairs, overlays: bool) -> Path:
    """OUT/database.db of the selections (and their verified pairs), an older one kept
    aside; OUT/overlays/ with them drawn, where asked."""
    out.mkdir(parents=True, exist_ok=True)
    db = out / "database.db"
    if db.exists():
        kept = keep_aside(db)
        log(f"{db} already existed: kept as {kept}; the new one is {db}")
    try:
        with atomic_path(db) as tmp:
            write_database(
                tmp,
                [v.camera for v in views],
                [v.name for v in views],
                [c.xy[s] for c, s in zip(pools, sel)],
                pairs,
                [c.descriptors[s] for c, s in zip(pools, sel)],
            )
            untrust_guessed_focals(tmp, views)
    except Exception as e:
        raise BenchError(f"cannot write {db}: {e}") from e
    shutil.rmtree(out / "overlays", ignore_errors=True)  # never beside another run's
    for v, c, s in zip(views, pools, sel) if overlays else ():
        path = (out / "overlays" / v.name).with_suffix(".png")
        path.parent.mkdir(parents=True, exist_ok=True)
        img = np.ascontiguousarray(v.image[..., ::-1])
        for x, y in c.xy[s] - 0.5:
            cv2.circle(img, (int(round(x)), int(round(y))), 3, (0, 255, 0), 1, cv2.LINE_AA)
        cv2.imwrite(str(path), img)
    return db


def select_to_database(request: SelectRequest, out: Path, seconds: dict | None = None) -> Path:
    """Write OUT/database.db (module docstring); returns its path. `seconds`, if given,
    receives the seconds of each step: read, the front end's (`stage.compute`), select,
    write (the database and the overlays)."""
    clock = {} if seconds is None else seconds
    out, cfg = Path(out), _checked(request, out)
    policy, budget = request.policy, request.budget
    t = time.perf_counter()
    views = load_image_folder(request.images, request.cameras)
    clock["read"] = time.perf_counter() - t
    if not all(v.posed for v in views):
        log("no poses (no --cameras): the geometry of the signals is estimated from the images")
    views, pools, sigs, front = compute(views, cfg.detector, cfg.signals, METHODS[policy].reads)
    clock |= {k: v for k, v in front.items() if v}
    budgets = () if METHODS[policy].whole_pool else (budget,)
    check_budgets(
        [len(c) for c in pools], budgets, f"the {len(views)} image(s) of {request.images}"
    )
    cams = [v.camera for v in views]
    step = time.perf_counter()
    unit = Unit(request.images.resolve().name, 0, policy, budget)
    sel, _, _ = select_match.select(views, pools, sigs, unit, cfg)
    pairs = select_match.match(cams, pools, sel, policy, cfg)[0] if request.match else []
    clock["select"] = time.perf_counter() - step
    step = time.perf_counter()
    db = _written(out, views, pools, sel, pairs, request.overlays)
    clock["write"] = time.perf_counter() - step
    n, kept = len(views), sum(len(s) for s in sel)
    seconds = f"{(time.perf_counter() - t) / n:.2f} s per image"
    if METHODS[policy].whole_pool:
        summary = f"{kept} keypoints in {n} images: the whole pool (--budget does not apply)"
    else:
        short = {v.name: len(s) for v, s in zip(views, sel) if len(s) < budget}
        if short:
            log(
                f"{len(short)} of {n} image(s) have fewer candidates than the budget {budget} "
                "per image and hold all of them: "
                + ", ".join(f"{k} ({m})" for k, m in list(short.items())[:5])
                + (", ..." if len(short) > 5 else "")
            )
        summary = f"{kept} keypoints in {n} images, {budget} per image"
        if short:
            lo, hi = min(short.values()), max(short.values())
            summary += f" (fewer in {len(short)} of them: {lo}" + (f" to {hi})" if hi > lo else ")")
    log(f"{policy}: {summary} ({seconds}){', matched' if request.match else ''}")
    return db


def keep_aside(path: Path) -> Path:
    """Move an existing file to the first free `<stem>.<n><suffix>` beside it (nothing a
    user wrote is replaced); returns the new name."""
    n = 1
    while (kept := path.with_name(f"{path.stem}.{n}{path.suffix}")).exists():
        n += 1
    path.rename(kept)
    return kept


def untrust_guessed_focals(path: Path, views: list[View]) -> None:
    """Mark the cameras of views whose focal length was guessed as COLMAP marks a guess:
    `has_prior_focal_length` false (the database's `prior_focal_length` 0)."""
    ids = camera_ids([v.camera for v in views])
    db = pycolmap.Database.open(str(path))
    try:
        for cid in sorted({cid for cid, v in zip(ids, views) if not v.focal_known}):
            cam = db.read_camera(cid)
            cam.has_prior_focal_length = False
            db.update_camera(cam)
    finally:
        db.close()
