"""`bench select`: the front end in front of classical SfM, on the user's own photographs.

images (+ optional COLMAP model) -> candidates and the signals the policy reads -> B per
image by a policy -> OUT/database.db (cameras, images, selected keypoints, COLMAP-format
SIFT descriptors;
with `match`, also matches and verified two-view geometries) and, with `overlays`,
OUT/overlays/<image>.png. The candidate pool of an image is its `max_candidates` strongest
detections (COLMAP's default feature count; the signals compare candidates pairwise, so a
12-megapixel pool must be bounded). The database is written under a temporary name, then
renamed.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bench import BenchError
from bench.backend.matching import BackendConfig, matcher
from bench.backend.reconstruction import write_database
from bench.console import log, progress
from bench.files import atomic_path
from bench.frontend import feedback, plugins
from bench.frontend.features import Candidates, DetectorConfig, detect
from bench.frontend.geometry import SignalConfig
from bench.frontend.policies import POLICIES, PolicyConfig, PolicyInput, check_policies
from bench.frontend.selection import select_views
from bench.frontend.signals import compute_signals
from bench.frontend.views import load_image_folder
from bench.vocabulary import METHODS


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
    policy_modules: tuple[str, ...] = ()
    max_candidates: int = 8192


def strongest(cand: Candidates, k: int) -> Candidates:
    """The k candidates of highest detector response (all if there are fewer), in their
    original order."""
    if len(cand) <= k:
        return cand
    keep = np.sort(np.argsort(-cand.response, kind="stable")[:k])
    return Candidates(
        cand.xy[keep],
        cand.size[keep],
        cand.angle[keep],
        cand.response[keep],
        cand.descriptors[keep],
    )


def select_to_database(request: SelectRequest, out: Path) -> Path:
    """Write OUT/database.db (module docstring); returns its path."""
    policy, budget = request.policy, request.budget
    plugins.load(request.policy_modules)
    check_policies([policy])
    if policy not in POLICIES and policy != feedback.NAME:
        raise BenchError(f"{policy} is not a selection policy; valid: a policy of `bench run`")
    det, backend = DetectorConfig(), BackendConfig()
    t = time.perf_counter()
    views = load_image_folder(request.images, request.cameras)
    if not all(v.posed for v in views):
        log("no poses (no --cameras): the geometry of the signals is estimated from the images")
    with progress("detect", len(views)) as bar:
        pools = []
        for v in views:
            pools.append(strongest(detect(v, det), request.max_candidates))
            bar.update()
    sigs, _ = compute_signals(views, pools, det, SignalConfig(), METHODS[policy].reads)
    cams = [v.camera for v in views]
    inputs = [PolicyInput(v, c, g) for v, c, g in zip(views, pools, sigs)]
    cfg = PolicyConfig(modules=tuple(request.policy_modules))
    sel, _ = select_views(policy, inputs, budget, 0, cfg, matcher(cams, pools, backend))
    pairs = matcher(cams, pools, backend)(sel) if request.match else []
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise BenchError(f"--out {out} is a file; give a folder for database.db")
    out.mkdir(parents=True, exist_ok=True)
    db = out / "database.db"
    if db.exists():
        log(f"replacing {db}")
    try:
        with atomic_path(db) as tmp:
            write_database(
                tmp,
                cams,
                [v.name for v in views],
                [c.xy[s] for c, s in zip(pools, sel)],
                pairs,
                [c.descriptors[s] for c, s in zip(pools, sel)],
            )
    except Exception as e:
        raise BenchError(f"cannot write {db}: {e}") from e
    shutil.rmtree(out / "overlays", ignore_errors=True)  # never beside another run's
    if request.overlays:
        for v, c, s in zip(views, pools, sel):
            path = (out / "overlays" / v.name).with_suffix(".png")
            path.parent.mkdir(parents=True, exist_ok=True)
            img = np.ascontiguousarray(v.image[..., ::-1])
            for x, y in c.xy[s] - 0.5:
                cv2.circle(img, (int(round(x)), int(round(y))), 3, (0, 255, 0), 1, cv2.LINE_AA)
            cv2.imwrite(str(path), img)
    short = {v.name: len(c) for v, c in zip(views, pools) if len(c) < budget}
    if short:
        log(
            f"{len(short)} image(s) have fewer candidates than the budget {budget} and hold "
            f"all of them: {', '.join(f'{k} ({n})' for k, n in list(short.items())[:5])}"
        )
    n = len(views)
    log(
        f"{policy}: {sum(len(s) for s in sel)} keypoints in {n} images, "
        f"{budget * n - sum(len(s) for s in sel)} short of {budget} per image "
        f"({(time.perf_counter() - t) / n:.2f} s per image){', matched' if request.match else ''}"
    )
    return db
