"""The front-end stage: the views of a render entry or dataset to candidate pools with
their signals, under the geometry a task grants (RIG: the views with their poses; IMAGES:
the views without them, the geometry estimated from the images).

A view larger than `DetectorConfig.max_image_size` is detected, and its signals computed,
on a downscaled copy (so every pixel threshold of the signals means what it means on the
rendered views); its candidates are returned in full-resolution pixels.

Cached (npz beside the render cache) by the render entry, the geometry granted, the
detector and signal settings and the code that computes them (`front_end` and what it
reaches, `bench.codehash`); the seconds measured when it was computed are stored with
it, so reported front-end times do not depend on whether the cache was warm.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, fields
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from bench import BenchError
from bench.codehash import code_hash
from bench.console import log
from bench.files import atomic_path, content_key
from bench.frontend import features
from bench.frontend.features import Candidates, DetectorConfig
from bench.frontend.geometry import IMAGES, RIG
from bench.frontend.signals import SIGNALS, TIMED, SignalConfig, Signals, compute_signals
from bench.frontend.views import View, load_views, source_key

_CAND = [f.name for f in fields(Candidates)]


@dataclass
class FrontEnd:
    """Everything the policies and the back end may see of one render entry."""

    views: list[View]
    pools: list[Candidates]
    signals: list[Signals]
    seconds: dict[str, float]
    """Measured seconds over all views: 'detect', 'geometry' and one per signal."""
    cached: bool


@cache
def frontend_code_hash() -> str:
    """Hash of the front end's code: `front_end` and what it reaches."""
    return code_hash([front_end])


def front_end(
    entry: Path,
    det: DetectorConfig,
    sig: SignalConfig,
    cache_dir: Path,
    grant: str = RIG,
    views: list[View] | None = None,
) -> FrontEnd:
    """Candidates and signals of every view of `entry` (a render entry or a dataset) under
    the geometry granted (RIG or IMAGES), computed or read from the cache; `views`: the
    entry's (`load_views`), shared between geometries so that each image is decoded once,
    and only when the cache misses."""
    entry = Path(entry)
    if grant not in (RIG, IMAGES):
        raise BenchError(f"unknown geometry {grant!r}; valid: {RIG}, {IMAGES}")
    views = load_views(entry) if views is None else views
    if grant == IMAGES:
        views = [v.without_pose() for v in views]
    key = content_key(
        {
            "entry": source_key(entry),
            "geometry": grant,
            "detector": asdict(det),
            "signals": asdict(sig),
            "opencv": cv2.__version__,
            "code": frontend_code_hash(),
        }
    )
    path = Path(cache_dir) / f"{entry.name}-{det.detector}-{grant}-{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as z:
                pools = [Candidates(*(z[f"{f}_{v}"] for f in _CAND)) for v in range(len(views))]
                sigs = [Signals(*(z[f"{s}_{v}"] for s in SIGNALS)) for v in range(len(views))]
                seconds = {k: float(z[f"seconds_{k}"]) for k in ("detect", *TIMED)}
            return FrontEnd(views, pools, sigs, seconds, cached=True)
        except (OSError, ValueError, KeyError):
            log(f"damaged front-end cache {path.name}; computing it again")
    t = time.perf_counter()
    work = [v.scale_to(det.max_image_size) for v in views]
    pools = [features.detect(v, det) for v, _, _ in work]
    seconds = {"detect": time.perf_counter() - t}
    sigs, sig_seconds = compute_signals([v for v, _, _ in work], pools, det, sig)
    seconds.update(sig_seconds)
    pools = [c.scaled(1 / sx, 1 / sy) for c, (_, sx, sy) in zip(pools, work)]
    arrays = {f"{f}_{v}": getattr(c, f) for v, c in enumerate(pools) for f in _CAND}
    arrays |= {f"{s}_{v}": getattr(g, s) for v, g in enumerate(sigs) for s in SIGNALS}
    arrays |= {f"seconds_{k}": np.float64(s) for k, s in seconds.items()}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            np.savez(tmp, **arrays)
    except OSError as e:
        raise BenchError(f"cannot write the front-end cache {path}: {e.strerror}") from e
    return FrontEnd(views, pools, sigs, seconds, cached=False)
