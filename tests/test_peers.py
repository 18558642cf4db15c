"""Stock COLMAP's extraction done once per image (`bench.backend.extraction.extract`): every
peer database built from it is the one COLMAP's own extractor builds."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from bench.backend import extraction
from bench.backend.database import quiet_colmap, write_images
from bench.backend.extraction import extract
from bench.backend.peers import write_extracted
from bench.frontend.views import Source, load_views


def _database(path: Path, images: Path, names, cams, extracted=None, max_features=0) -> dict:
    """What a database holds after extraction: stock (`extracted` None) or built from
    `extract`; then matched exhaustively as the peers match."""
    db = pycolmap.Database.open(str(path))
    write_images(db, cams, names)
    if extracted is not None:
        write_extracted(db, cams, extracted)
    db.close()
    if extracted is None:
        options = pycolmap.FeatureExtractionOptions()
        options.num_threads = 1
        if max_features:
            options.sift.max_num_features = max_features
        with quiet_colmap():
            pycolmap.extract_features(
                path, images, image_names=names, extraction_options=options,
                device=pycolmap.Device.cpu,
            )  # fmt: skip
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = 1
    with quiet_colmap():
        pycolmap.match_exhaustive(path, matching_options=matching, device=pycolmap.Device.cpu)
    db = pycolmap.Database.open(str(path))
    try:
        return {
            "rigs": [str(r.todict()) for r in db.read_all_rigs()],
            "cameras": [str(c.todict()) for c in db.read_all_cameras()],
            "keypoints": [db.read_keypoints(k + 1) for k in range(len(names))],
            "descriptors": [db.read_descriptors(k + 1).data for k in range(len(names))],
            "matches": (db.num_matches(), db.num_inlier_matches()),
        }
    finally:
        db.close()


def test_the_extraction_cache_is_keyed_by_the_limit_and_the_code(
    medium_entry, tmp_path, monkeypatch
):
    """One cache folder for every limit: an extraction cached at one SIFT limit is never
    read back at another, nor after the extraction's code changed."""
    entry = medium_entry("table")
    images, views = Source.of(entry).images, load_views(entry)[:1]
    names, cams, cache = [v.name for v in views], [v.camera for v in views], tmp_path / "sift"
    full = extract(images, names, cams, 0, cache)[0]
    capped = extract(images, names, cams, 64, cache)[0]
    assert len(capped.keypoints) < len(full.keypoints)  # 64 locations, some two orientations
    calls, real = [], extraction._extract_now
    monkeypatch.setattr(extraction, "_extract_now", lambda *a: calls.append(a[3]) or real(*a))
    extract(images, names, cams, 64, cache)
    assert calls == []  # the same limit and code: read back
    monkeypatch.setattr(extraction, "code_hash", lambda modules: "edited")
    extract(images, names, cams, 64, cache)
    assert calls == [64]


@pytest.mark.parametrize("max_features", [0, 64])
def test_a_database_built_from_the_cached_extraction_is_colmaps_own(
    medium_entry, tmp_path, monkeypatch, max_features
):
    entry = medium_entry("table")
    images, views = Source.of(entry).images, load_views(entry)
    names, cams = [v.name for v in views], [v.camera for v in views]
    cache = tmp_path / "sift"
    ours = extract(images, names, cams, max_features, cache)
    assert len(list(cache.iterdir())) == len(names) and all(e.seconds > 0 for e in ours)
    work = Path(tempfile.mkdtemp(dir=tmp_path))
    stock = _database(work / "stock.db", images, names, cams, max_features=max_features)
    built = _database(work / "built.db", images, names, cams, ours)
    assert built["rigs"] == stock["rigs"] and built["cameras"] == stock["cameras"]
    for key in ("keypoints", "descriptors"):
        for a, b in zip(built[key], stock[key]):
            np.testing.assert_array_equal(a, b)
    assert built["matches"] == stock["matches"] and stock["matches"][1] > 0

    def never(*args):
        raise AssertionError("extracted again")

    monkeypatch.setattr(extraction, "_extract_now", never)  # a bag of some images: all cached
    bag = [2, 0, 3]
    again = extract(images, [names[k] for k in bag], [cams[k] for k in bag], max_features, cache)
    for e, k in zip(again, bag):
        np.testing.assert_array_equal(e.keypoints, ours[k].keypoints)
        assert e.seconds == ours[k].seconds  # the seconds measured when it was computed
