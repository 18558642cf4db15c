"""Stock COLMAP as the peer of the `sfm` and `pairs` tasks: what a user would run instead of
a selection policy, on the same images, scored the same way.

* `colmap`: pycolmap's own SIFT extraction at its default settings (8192 features at most),
  exhaustive matching with COLMAP's own verification, incremental mapping with the same
  known, fixed intrinsics (`bench.backend.reconstruction.map_database`).
* `colmap-b`: the same extraction, then exactly B keypoints per view (all of them where
  COLMAP found fewer) in COLMAP's own priority, largest scale first, ties by COLMAP's
  order (`hard_cap`); what the Image Matching Benchmark's restricted-keypoint track does.
* `colmap-soft-b`: SIFT's maximum number of features set to B. COLMAP's limit is soft: it
  keeps whole scale levels (octaves) until the limit is reached, so a view holds more (up
  to about twice) or fewer features than B; its rows record how many.
* `colmap-tracks-b`, the peer of the selections that see other views (`sees`: `views`,
  issue 53): a first pass of the same extraction held to `track-first`'s first pass (4B
  per view, `hard_cap`), matched exhaustively and verified by COLMAP; then in each view
  the B keypoints whose verified track (connected component of the verified matches)
  spans the most views, ties in COLMAP's order (`track_cap`); those B are matched and
  verified again by COLMAP, and mapped, like `colmap-b`'s. Its rows' `select_ms` is the
  first pass's matching and the choice.

The modern peers, `aliked-b`, `disk-b` and `xfeat-b`, each pool's own top-B, are declared
with the pools (`bench.unit.pooled`).

For the `pairs` task of the COLMAP peers, each pair's relative pose is estimated from the pair's verified
matches (COLMAP's own verification, read back from its database) by the policies'
verification (`bench.backend.matching.verify`: COLMAP's calibrated two-view geometry with
the known intrinsics, seeded); COLMAP's matcher stores no pose.

COLMAP's extraction of an image depends on that image alone (and SIFT's limit), so it is
done once per image and limit and cached (`bench.backend.extraction.extract`: beside the front-end cache, under
`COLMAP_SIFT`), with the seconds it took; every database of a peer, one per unit (a
dataset's bags among them), is built from it as COLMAP's extractor builds it.

The peers read the images and the intrinsics only, like every back end.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
import pycolmap

from bench.backend.database import camera_ids, quiet_colmap, write_images
from bench.backend.extraction import Extracted, extract
from bench.backend.matching import BackendConfig, PairMatches, verify
from bench.backend.reconstruction import Reconstruction, map_database
from bench.camera import Camera
from bench.frontend.pools import strongest_first
from bench.frontend.tracks import track_views
from bench.vocabulary import (
    OWN_PIPELINE,
    TRACKS_FIRST_PASS,
    TRACKS_PEER,
    Method,
    declare_kind,
    declare_method,
)


@dataclass
class PeerRun:
    """A peer's reconstruction and what its front end produced."""

    recs: dict[str, Reconstruction]
    """Per track protocol, the mapper's result."""
    keypoints: list[np.ndarray]
    """Per view, COLMAP's keypoints (COLMAP's pixel convention)."""
    tentative: int
    verified: int
    seconds: dict[str, float]
    pairs: list[PairMatches]
    """The verified pairs with their relative poses (for a task that does not map)."""
    pose_s: float
    """The seconds their poses took."""


def keypoint_scales(keypoints: np.ndarray) -> np.ndarray:
    """The scale of COLMAP's affine keypoints (x, y, a11, a12, a21, a22): the mean length
    of the two columns of the affine shape (COLMAP's `FeatureKeypoint::ComputeScale`)."""
    a = np.asarray(keypoints, np.float64)
    return (np.hypot(a[:, 2], a[:, 4]) + np.hypot(a[:, 3], a[:, 5])) / 2


def hard_cap(keypoints: np.ndarray, budget: int) -> np.ndarray:
    """Indices of the `budget` largest-scale keypoints, ties by index, in COLMAP's order."""
    order = strongest_first(keypoint_scales(keypoints))
    return np.sort(order[:budget])


def _keep_in_database(db_path: Path, names: list[str], choose) -> None:
    """Keep of every image only the keypoints (and descriptors) `choose(view, keypoints)`
    names (ascending indices)."""
    db = pycolmap.Database.open(str(db_path))
    try:
        ids = {img.name: img.image_id for img in db.read_all_images()}
        kept = {}
        for v, name in enumerate(names):
            kps, desc = db.read_keypoints(ids[name]), db.read_descriptors(ids[name])
            keep = choose(v, kps)
            kept[ids[name]] = kps[keep], pycolmap.FeatureDescriptors(desc.type, desc.data[keep])
        db.clear_keypoints()
        db.clear_descriptors()
        for image_id, (kps, desc) in kept.items():
            db.write_keypoints(image_id, kps)
            db.write_descriptors(image_id, desc)
    finally:
        db.close()


COLMAP_SIFT = "colmap-sift"
"""The folder of `extract`'s cache, beside the front end's (`--renders`)."""


def peer_extraction(
    image_dir: Path,
    names: list[str],
    cams: list[Camera],
    peer: str,
    budget: int,
    cache_dir: Path | None = None,
) -> list[Extracted]:
    """What a stock-COLMAP peer's database holds of each view at `budget`: `extract` at
    the peer's SIFT limit, capped as its `CAPS` says (`hard_cap`)."""
    cap = CAPS[peer]
    extracted = extract(image_dir, names, cams, budget if cap == SOFT else 0, cache_dir)
    if cap not in (HARD, TRACKS):
        return extracted
    keep = budget if cap == HARD else TRACKS_FIRST_PASS * budget
    kept = [hard_cap(e.keypoints, keep) for e in extracted]
    return [Extracted(e.keypoints[k], e.descriptors[k], e.seconds) for e, k in zip(extracted, kept)]


def write_extracted(db: pycolmap.Database, cams: list[Camera], extracted: list[Extracted]) -> None:
    """Into a database holding the views' images (`write_images`, ids 1..n), what COLMAP's
    extractor writes: a rig per camera (its reference sensor), in the order of the images
    that first use it, then each image's keypoints and descriptors."""
    for cid in dict.fromkeys(camera_ids(cams)):
        rig = pycolmap.Rig()
        rig.add_ref_sensor(pycolmap.sensor_t(pycolmap.SensorType.CAMERA, cid))
        db.write_rig(rig)
    for image_id, e in enumerate(extracted, start=1):
        db.write_keypoints(image_id, e.keypoints)
        descriptors = pycolmap.FeatureDescriptors(pycolmap.FeatureExtractorType.SIFT, e.descriptors)
        db.write_descriptors(image_id, descriptors)


def longest_tracks(spans: np.ndarray, budget: int) -> np.ndarray:
    """Indices of the `budget` keypoints whose tracks span the most views (`spans`), ties
    in COLMAP's order (by index), ascending."""
    order = np.lexsort((np.arange(len(spans)), -np.asarray(spans)))
    return np.sort(order[:budget])


def track_cap(db_path: Path, names: list[str], budget: int, matching, verification) -> None:
    """`colmap-tracks-b`'s choice (module docstring): its first pass (the database's
    keypoints, held to `TRACKS_FIRST_PASS` x B, track-first's) matched and verified by COLMAP, then in each
    view the `budget` keypoints of the longest verified tracks; the first pass's matches
    are cleared for the final matching."""
    pycolmap.match_exhaustive(
        db_path,
        matching_options=matching,
        verification_options=verification,
        device=pycolmap.Device.cpu,
    )
    db = pycolmap.Database.open(str(db_path))
    try:
        ids = {img.name: img.image_id for img in db.read_all_images()}
        views = [ids[n] for n in names]
        sizes = [db.num_keypoints_for_image(i) for i in views]
        pairs = []
        for i, j in combinations(range(len(views)), 2):
            if db.exists_two_view_geometry(views[i], views[j]):
                tvg = db.read_two_view_geometry(views[i], views[j])
                inliers = np.asarray(tvg.inlier_matches, np.int64).reshape(-1, 2)
                config = pycolmap.TwoViewGeometryConfiguration(int(tvg.config)).name
                pairs.append(PairMatches(i, j, inliers[:0], inliers, config))
        db.clear_matches()
        db.clear_two_view_geometries()
    finally:
        db.close()
    spans = track_views(sizes, pairs)
    _keep_in_database(db_path, names, lambda v, _: longest_tracks(spans[v], budget))


def verified_pairs(
    db: pycolmap.Database,
    ids: list[int],
    cams: list[Camera],
    keypoints: list[np.ndarray],
    cfg: BackendConfig,
) -> list[PairMatches]:
    """Every pair of views (i < j, image ids `ids`) with COLMAP's verified matches, and the
    relative pose of those matches (module docstring)."""
    out = []
    for i, j in combinations(range(len(ids)), 2):
        if not db.exists_two_view_geometry(ids[i], ids[j]):
            continue
        tvg = db.read_two_view_geometry(ids[i], ids[j])
        inliers = np.asarray(tvg.inlier_matches, np.int64).reshape(-1, 2)
        pose = verify(cams[i], keypoints[i], cams[j], keypoints[j], inliers, cfg)[2]
        config = pycolmap.TwoViewGeometryConfiguration(int(tvg.config)).name
        out.append(PairMatches(i, j, inliers[:0], inliers, config, pose))
    return out


def run_peer(
    names: list[str],
    cams: list[Camera],
    extracted: list[Extracted],
    cfg: BackendConfig,
    protocols: list[str],
    keep_tracks: int = 0,
) -> PeerRun:
    """Match the peer's extraction of the views (`peer_extraction`) once with stock COLMAP,
    estimate each verified pair's relative pose, then map under each track protocol (see
    the module docstring)."""
    work = Path(tempfile.mkdtemp(prefix="bench-peer-"))
    db_path = work / "database.db"
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = 1
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = cfg.seed
    try:
        t = time.perf_counter()
        db = pycolmap.Database.open(str(db_path))
        try:  # the known intrinsics: COLMAP's extractor keeps the camera of an image it finds
            write_images(db, cams, names)
            write_extracted(db, cams, extracted)
        finally:
            db.close()  # the seconds of extraction as measured when it was computed
        detect_s = time.perf_counter() - t + sum(e.seconds for e in extracted)
        with quiet_colmap():
            t = time.perf_counter()
            if keep_tracks:
                track_cap(db_path, names, keep_tracks, matching, verification)
            select_s = time.perf_counter() - t
            t = time.perf_counter()
            pycolmap.match_exhaustive(
                db_path,
                matching_options=matching,
                verification_options=verification,
                device=pycolmap.Device.cpu,
            )
            match_s = time.perf_counter() - t
        db = pycolmap.Database.open(str(db_path))
        try:
            ids = {img.name: img.image_id for img in db.read_all_images()}
            keypoints = [db.read_keypoints(ids[n])[:, :2] for n in names]
            tentative, verified = db.num_matches(), db.num_inlier_matches()
            t = time.perf_counter()
            pairs = verified_pairs(db, [ids[n] for n in names], cams, keypoints, cfg)
            pose_s = time.perf_counter() - t
        finally:
            db.close()
        recs = {pr: map_database(db_path, cfg, pr) for pr in protocols}
        seconds = {"detect": detect_s, "match": match_s}
        if keep_tracks:
            seconds["select"] = select_s
        return PeerRun(recs, keypoints, tentative, verified, seconds, pairs, pose_s)
    finally:
        shutil.rmtree(work, ignore_errors=True)


HARD, SOFT, TRACKS = "hard", "soft", "tracks"
CAPS = {"colmap": None, "colmap-b": HARD, "colmap-soft-b": SOFT, "colmap-tracks-b": TRACKS}
"""How each stock-COLMAP peer holds its extraction to the budget: not at all (COLMAP's
default, budget 0), exactly B keypoints (`hard_cap`), SIFT's own soft limit, or the B of
the longest verified tracks of a first pass (`track_cap`)."""
declare_kind(
    TRACKS_PEER,
    "extracts and matches with stock COLMAP, keeps in each view the keypoints of the "
    "longest verified tracks, matches them again and maps (colmap-tracks-b)",
    budget=f"the keypoints each view keeps: the B of the longest verified tracks of a first "
    f"pass of {TRACKS_FIRST_PASS} x B",
)
for m in (  # peer rows: `colmap` (budget 0: COLMAP's default), the others one per budget
    Method("colmap", "COLMAP default SIFT (peer)", "peer", True, kind=OWN_PIPELINE),
    Method("colmap-b", "COLMAP SIFT, B largest-scale (peer)", "peer", kind=OWN_PIPELINE),
    Method("colmap-soft-b", "COLMAP SIFT soft limit B (peer)", "peer", kind=OWN_PIPELINE),
    Method(
        "colmap-tracks-b",
        "COLMAP SIFT, B of the longest tracks of 4B (peer)",
        "peer",
        kind=TRACKS_PEER,
    ),
):
    declare_method(m)
