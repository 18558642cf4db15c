"""Stock COLMAP's SIFT extraction of one image at a time, cached by what decides it: the
image's bytes, SIFT's limit, pycolmap's version and this module's code alone (its import
closure holds the database's first rows and nothing else of the back end, so a change of
how the back end matches, verifies or maps extracts nothing again). The peers build every
database from it (`bench.backend.peers`)."""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from bench.backend.database import quiet_colmap, write_images
from bench.camera import Camera
from bench.codehash import code_hash
from bench.files import atomic_path, content_key

EXTRACTION_CODE = ("bench.backend.extraction",)
"""Where the code that decides an extraction starts (its import closure)."""


@dataclass
class Extracted:
    """COLMAP's SIFT extraction of one image: what its database holds of it."""

    keypoints: np.ndarray
    """N x 6 affine keypoints (COLMAP's pixel convention), float32."""
    descriptors: np.ndarray
    """N x 128 SIFT descriptors, uint8."""
    seconds: float
    """The seconds its extraction took when it was computed (cached with it)."""


def extract(
    image_dir: Path,
    names: list[str],
    cams: list[Camera],
    max_features: int = 0,
    cache_dir: Path | None = None,
) -> list[Extracted]:
    """Stock COLMAP's SIFT extraction of each image (single-threaded, on the CPU) at SIFT's
    limit `max_features` (0: COLMAP's default), each image read from `cache_dir` where it
    holds it (keyed by the image's bytes, the limit, pycolmap's version and this module's
    code), the others
    extracted together and cached there; without `cache_dir`, extracted every call."""
    keys = [_extraction_key(Path(image_dir) / n, max_features) for n in names]
    paths = [None if cache_dir is None else Path(cache_dir) / f"{k}.npz" for k in keys]
    out: list[Extracted | None] = [_read_extracted(p) for p in paths]
    missing = [k for k, e in enumerate(out) if e is None]
    if missing:
        new = _extract_now(
            image_dir, [names[k] for k in missing], [cams[k] for k in missing], max_features
        )
        for k, e in zip(missing, new):
            out[k] = e
            if paths[k] is not None:
                paths[k].parent.mkdir(parents=True, exist_ok=True)
                with atomic_path(paths[k]) as tmp:
                    np.savez(
                        tmp, keypoints=e.keypoints, descriptors=e.descriptors, seconds=e.seconds
                    )
    return out


def _extraction_key(image: Path, max_features: int) -> str:
    digest = hashlib.sha256(image.read_bytes()).hexdigest()
    code = code_hash(EXTRACTION_CODE)  # the extraction's options among it
    return content_key(
        {"image": digest, "max": max_features, "pycolmap": pycolmap.__version__, "code": code}
    )


def _read_extracted(path: Path | None) -> Extracted | None:
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path) as z:
            return Extracted(z["keypoints"], z["descriptors"], float(z["seconds"]))
    except (OSError, ValueError, KeyError):
        return None  # damaged: extracted again


def _extract_now(image_dir: Path, names: list[str], cams: list[Camera], max_features: int):
    """COLMAP's extraction of the images, each timed alone (into a database of its own)."""
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = 1
    if max_features:
        extraction.sift.max_num_features = max_features
    out = []
    work = Path(tempfile.mkdtemp(prefix="bench-sift-"))
    try:
        for k, (name, cam) in enumerate(zip(names, cams)):
            db_path = work / f"{k}.db"
            db = pycolmap.Database.open(str(db_path))
            try:  # the known intrinsics: COLMAP's extractor keeps the camera it finds
                write_images(db, [cam], [name])
            finally:
                db.close()
            t = time.perf_counter()
            with quiet_colmap():
                pycolmap.extract_features(
                    db_path,
                    image_dir,
                    image_names=[name],
                    extraction_options=extraction,
                    device=pycolmap.Device.cpu,
                )
            seconds = time.perf_counter() - t
            db = pycolmap.Database.open(str(db_path))
            try:
                kps, desc = db.read_keypoints(1), db.read_descriptors(1)
            finally:
                db.close()
            out.append(Extracted(np.asarray(kps, np.float32), np.asarray(desc.data), seconds))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out
