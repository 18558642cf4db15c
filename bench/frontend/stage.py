"""The front-end stage: the views of a render entry or dataset to candidate pools with
their signals, under the geometry a task grants (RIG: the views with their poses; IMAGES:
the views without them, the geometry estimated from the images).

A view larger than `DetectorConfig.max_image_size` is detected, and its signals computed,
on a downscaled copy (so every pixel threshold of the signals means what it means on the
rendered views); its candidates are returned in full-resolution pixels. Views whose focal
length is a guess (photographs without EXIF) get the focal length estimated from the
images (`bench.frontend.geometry.estimate_focal`) before the signals read the geometry.
`compute` is this stage for any views (`bench select` calls it on a folder of
photographs, with the signals its policy reads); `front_end` caches it for a render
entry, a dataset or a folder of images (`bench frontend`, the stage alone); `subset` is
the front end of some of its views alone (a dataset's bag), cached beside it by
`bag_front_end`.

Cached (npz beside the render cache) by the render entry, the geometry granted, the
detector and signal settings (and a pool's packages' versions, `Pool.identity`) and the code
that computes them (`compute` and what it reaches, `bench.codehash`; not this caching
around it); the seconds measured when it was computed are stored with
it, so reported front-end times do not depend on whether the cache was warm. A front end
of large views (photographs, `PROGRESS_PIXELS`) shows its own progress while computed, a
step per view detected and per view's signals.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.codehash import code_hash, library_versions
from bench.console import log, progress
from bench.files import atomic_path, content_key
from bench.frontend import features
from bench.frontend.features import Candidates, DetectorConfig
from bench.frontend.geometry import IMAGES, RIG, SignalConfig, estimate_focal, focal_camera
from bench.frontend.pools import POOLS
from bench.frontend.signals import (
    SIGNALS,
    TIMED,
    Signals,
    compute_signals,
    repeatability_redetect,
)
from bench.frontend.views import View, load_views, pixels_key, source_key

_CAND = [f.name for f in fields(Candidates)]
VIEW_ALONE = ("repeatability_redetect",)
"""The costly signal that reads one view alone (four perturbed re-detections of it):
`subset` takes the whole front end's (`compute_signals` computes the others cheaply, or,
as ambiguity, parallax and epipolar, from the other views)."""
PROGRESS_PIXELS = 2_000_000
"""A front end whose largest view holds at least this many pixels shows its progress (a
photograph's takes seconds a view, 8 views of 6 MP 238 s; a render's less than one)."""


@dataclass
class FrontEnd:
    """Everything the policies and the back end may see of one render entry."""

    views: list[View]
    pools: list[Candidates]
    signals: list[Signals]
    seconds: dict[str, float]
    """Measured seconds over all views: 'detect', 'geometry' and one per signal."""
    cached: bool


FRONTEND_CODE = ("bench.frontend.stage",)
"""Where the front end's code starts (`compute`, `view_alone`, `subset`): its import closure."""


def front_end(
    entry: Path,
    det: DetectorConfig,
    sig: SignalConfig,
    cache_dir: Path,
    grant: str = RIG,
    views: list[View] | None = None,
    bagged: bool = False,
) -> FrontEnd:
    """Candidates and signals of every view of `entry` (a render entry or a dataset, or a
    folder of images alone with its views given) under the geometry granted (RIG or
    IMAGES), computed or read from the cache; `views`: the entry's (`load_views`, or
    `load_image_folder` for a folder of images), shared between geometries so that each
    image is decoded once, and only when the cache misses. `bagged` (every unit reads a bag
    of its views, whose other signals are the bag's own): only what `subset` takes of it
    (`view_alone`)."""
    entry = Path(entry)
    if grant not in (RIG, IMAGES):
        raise BenchError(f"unknown geometry {grant!r}; valid: {RIG}, {IMAGES}")
    views = load_views(entry) if views is None else views
    if grant == IMAGES:
        views = [v.without_pose() for v in views]
    path = cache_file(entry, det, sig, cache_dir, grant, bagged)
    cached = _read(path, views)
    if cached is not None:
        return cached
    large = max((v.camera.width * v.camera.height for v in views), default=0) >= PROGRESS_PIXELS
    with progress("features", 2 * len(views), "step", shown=large) as bar:
        bar.set_postfix_str(f"{entry.name}, {grant}")
        _, pools, sigs, seconds = (view_alone if bagged else compute)(
            views, det, sig, step=bar.update
        )
    return _write(path, FrontEnd(views, pools, sigs, seconds, cached=False))


def bag_front_end(
    entry: Path,
    det: DetectorConfig,
    sig: SignalConfig,
    cache_dir: Path,
    grant: str,
    full: FrontEnd,
    keep: tuple[int, ...],
) -> FrontEnd:
    """`subset(full, keep, ...)` of `full`, the bagged `front_end` of `entry` under `grant`,
    computed or read from the cache beside it: a bag's signals are computed once, not by
    every worker that holds the bag."""
    name = cache_file(entry, det, sig, cache_dir, grant, bagged=True).stem
    path = Path(cache_dir) / f"{name}-bag-{content_key(list(keep))}.npz"
    cached = _read(path, [full.views[i] for i in keep])
    return cached if cached is not None else _write(path, subset(full, keep, det, sig))


def cache_file(
    entry: Path, det: DetectorConfig, sig: SignalConfig, cache_dir, grant, bagged=False
) -> Path:
    """The cache file of `front_end` (`bench frontend` prints it), named by what decides
    it (module docstring)."""
    key = content_key(
        {
            "entry": source_key(entry),
            "pixels": pixels_key(entry),
            "geometry": grant,
            "detector": asdict(det),
            "signals": asdict(sig),
            "libraries": library_versions(),
            "code": code_hash(FRONTEND_CODE),
            "alone": bagged,
        }
        | POOLS[det.detector].identity()
    )
    part = "-alone" if bagged else ""
    return Path(cache_dir) / f"{Path(entry).name}-{det.detector}-{grant}{part}-{key}.npz"


def _read(path: Path, views: list[View]) -> FrontEnd | None:
    """The front end of `views` cached at `path`; None where there is none (or it is damaged)."""
    if not path.is_file():
        return None
    try:
        with np.load(path) as z:
            pools = [Candidates(*(z[f"{f}_{v}"] for f in _CAND)) for v in range(len(views))]
            sigs = [Signals(*(z[f"{s}_{v}"] for s in SIGNALS)) for v in range(len(views))]
            seconds = {k[8:]: float(z[k]) for k in z.files if k.startswith("seconds_")}
        return FrontEnd(views, pools, sigs, seconds, cached=True)
    except (OSError, ValueError, KeyError):
        log(f"damaged front-end cache {path.name}; computing it again")
        return None


def _write(path: Path, fe: FrontEnd) -> FrontEnd:
    """Cache `fe` at `path` (written to a temporary name, then renamed); returns it."""
    arrays = {f"{f}_{v}": getattr(c, f) for v, c in enumerate(fe.pools) for f in _CAND}
    arrays |= {f"{s}_{v}": getattr(g, s) for v, g in enumerate(fe.signals) for s in SIGNALS}
    arrays |= {f"seconds_{k}": np.float64(s) for k, s in fe.seconds.items()}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            np.savez(tmp, **arrays)
    except OSError as e:
        raise BenchError(f"cannot write the front-end cache {path}: {e.strerror}") from e
    return fe


def subset(full: FrontEnd, keep: tuple[int, ...], det: DetectorConfig, sig: SignalConfig):
    """The front end of the views `keep` of `full` alone: their candidates and the signals
    that read a view alone (`VIEW_ALONE`) as `full` holds them, the others computed on
    these views alone as `compute` computes them (on each view downscaled to
    `det.max_image_size`); their seconds are `full`'s share per view of detection and the
    view-alone signals, and their own of the others."""
    views = [full.views[i] for i in keep]
    work = [v.scale_to(det.max_image_size) for v in views]
    pools = [full.pools[i] for i in keep]
    scaled = [c.scaled(sx, sy) for c, (_, sx, sy) in zip(pools, work)]
    wanted = tuple(s for s in SIGNALS if s not in VIEW_ALONE)
    sigs, seconds = compute_signals([v for v, _, _ in work], scaled, det, sig, wanted)
    sigs = [
        replace(g, **{s: getattr(full.signals[i], s) for s in VIEW_ALONE})
        for g, i in zip(sigs, keep)
    ]
    share = len(keep) / len(full.views)
    seconds |= {k: full.seconds[k] * share for k in ("detect", *VIEW_ALONE)}
    return FrontEnd(views, pools, sigs, seconds, cached=False)


def with_focal(view: View, factor: float) -> View:
    """The view with focal length factor x max(width, height)."""
    return replace(view, camera=focal_camera(view.camera, factor))


def compute(
    views: list[View],
    det: DetectorConfig,
    sig: SignalConfig,
    wanted: tuple[str, ...] = SIGNALS,
    step=None,
) -> tuple[list[View], list[Candidates], list[Signals], dict[str, float]]:
    """The stage on any views (module docstring): the views (with the focal length
    estimated where it was guessed), their candidates in full-resolution pixels, the
    signals (`wanted`: those a caller's policy reads, `compute_signals`) and the seconds;
    `step()`, if given, is called as each view is detected and its signals computed."""
    t = time.perf_counter()
    work = [v.scale_to(det.max_image_size) for v in views]
    pools = []
    for v, _, _ in work:
        pools.append(features.detect(v, det))
        if step is not None:
            step()
    seconds = {"detect": time.perf_counter() - t}
    t = time.perf_counter()
    if not all(v.focal_known for v in views):
        views, work = _estimate_focal(views, work, pools, sig)
    focal_s = time.perf_counter() - t
    sigs, sig_seconds = compute_signals([v for v, _, _ in work], pools, det, sig, wanted, step)
    seconds.update(sig_seconds)
    seconds["geometry"] += focal_s
    pools = [c.scaled(1 / sx, 1 / sy) for c, (_, sx, sy) in zip(pools, work)]
    return views, pools, sigs, seconds


def view_alone(views: list[View], det: DetectorConfig, sig: SignalConfig, step=None):
    """`compute` without what `subset` computes again on a bag's views: the candidates and
    the view-alone signals (`VIEW_ALONE`), the others 0, the views' geometry not estimated
    (on kitti-seq2, 51 frames in bags of 6, the whole set's geometry took 1,323 of a bag
    run's 2,033 s and no bag read it). Its values are `compute`'s wherever `subset` reads
    them (tests/test_bags.py)."""
    t = time.perf_counter()
    work = [v.scale_to(det.max_image_size) for v in views]
    pools = [features.detect(v, det) for v, _, _ in work]
    seconds = dict.fromkeys(TIMED, 0.0) | {"detect": time.perf_counter() - t}
    if not all(v.focal_known for v in views):
        t = time.perf_counter()
        views, work = _estimate_focal(views, work, pools, sig)
        seconds["geometry"] = time.perf_counter() - t
    sigs = []
    for (v, _, _), cand in zip(work, pools):
        t = time.perf_counter()
        redetect = repeatability_redetect(v.gray, cand, det)
        seconds["repeatability_redetect"] += time.perf_counter() - t
        zero = {s: np.zeros(len(cand)) for s in SIGNALS}
        sigs.append(Signals(**zero | {"repeatability_redetect": redetect}))
        if step is not None:
            step(2)
    pools = [c.scaled(1 / sx, 1 / sy) for c, (_, sx, sy) in zip(pools, work)]
    return views, pools, sigs, seconds


def _estimate_focal(views, work, pools, sig):
    """`views` and their working copies with the focal length of the guessed ones
    estimated from the images (kept as guessed where it cannot be), said in one line."""
    guessed = [v for v in views if not v.focal_known]
    what = f"{len(guessed)} image(s) have no known focal length (no EXIF, no camera model)"
    found = estimate_focal([v for v, _, _ in work], pools, sig)
    if found.factor is None:
        log(
            f"{what}: it is guessed, 1.2 x max(width, height), because the images do not "
            f"determine it: {found.why}; the geometry of the signals may be poor: give a "
            "model of the cameras (bench select --cameras; a dataset)"
        )
        return views, work
    factor, pairs = found.factor, found.pairs
    c = guessed[0].camera
    log(
        f"{what}: guessed, then estimated from {pairs} pairs of images: {factor:.3f} x "
        f"max(width, height) ({factor * max(c.width, c.height):.0f} px at {c.width}x{c.height}); "
        "recorded as an untrusted prior"
    )
    views = [v if v.focal_known else with_focal(v, factor) for v in views]
    work = [(v if v.focal_known else with_focal(v, factor), sx, sy) for v, sx, sy in work]
    return views, work
