"""The reference renders: views shipped as lossless files under a SHA-256 manifest, read by
default where the set holds the rig under the current render key, checked on every read,
their ground truth recomputed by the AOV pass alone."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from bench import BenchError, files
from bench.render import entry as render
from bench.render import reference
from bench.render.config import RenderConfig
from tests.conftest import TINY
from tests.test_render import assert_ground_truth_projects


@pytest.fixture
def shipped(tiny_entry, tmp_path, monkeypatch):
    """A reference set made from the session's tiny table entry, in place of the real one;
    returns (its root, the rendered entry it was made from, a fresh renders folder)."""
    made = tiny_entry("table")
    root = tmp_path / "reference"
    reference.write_reference([render.reference_input(made)], root)
    monkeypatch.setattr(reference, "REFERENCE", root)
    return root, made, tmp_path / "renders"


def test_an_entry_from_the_reference_set_has_its_pixels_and_recomputed_truth(shipped):
    root, made, renders = shipped
    manifest = json.loads((root / reference.MANIFEST).read_text())
    assert list(manifest["rigs"]) == [f"table-s0-v{TINY.views}"]
    assert all(n.endswith(".webp") for n in manifest["images"])
    entry = render.render_scene("table", 0, TINY, renders)
    assert entry.parent.name == reference.SUBFOLDER and entry.name == made.name
    for v in range(TINY.views):  # lossless: the same 8-bit values as the path-traced view
        a, b = (cv2.imread(str(e / render.image_name(v))) for e in (entry, made))
        np.testing.assert_array_equal(a, b)
        ta, tb = (np.load(e / render.truth_name(v)) for e in (entry, made))
        assert np.array_equal(ta["normal"], tb["normal"], equal_nan=True)
        assert np.array_equal(ta["shape_index"], tb["shape_index"], equal_nan=True)
        np.testing.assert_allclose(ta["position"], tb["position"], rtol=0, atol=1e-4)
    meta = files.read_meta(entry)
    assert (
        meta["pixels"]
        == files.read_meta(made)["pixels"]
        == manifest["rigs"][f"table-s0-v{TINY.views}"]["pixels"]
    )
    assert meta["made_by"]["variant"] == meta["variant"] == files.read_meta(made)["variant"]
    assert_ground_truth_projects(entry, TINY.views)
    assert render.known_pixels("table", 0, TINY, renders) == meta["pixels"]


def test_a_missing_or_altered_reference_file_is_named_and_refused(shipped):
    root, _, renders = shipped
    image = sorted((root / "images").rglob("*.webp"))[1]
    data = bytearray(image.read_bytes())
    data[-5] ^= 0xFF
    image.write_bytes(bytes(data))
    with pytest.raises(BenchError, match=rf"{image.name} is altered \(SHA-256"):
        render.render_scene("table", 0, TINY, renders)
    image.unlink()
    with pytest.raises(BenchError, match=rf"{image.name} is missing; restore it"):
        render.render_scene("table", 0, TINY, renders)
    assert not (renders / reference.SUBFOLDER).exists() or not any(
        (renders / reference.SUBFOLDER).iterdir()
    )


def test_every_shipped_view_is_checked_also_behind_a_filled_cache(shipped):
    """Each view in turn, view 0 included, altered after the cache was filled: the cached
    copy is not used silently (`bench run` takes it through `cached_entry`)."""
    root, _, renders = shipped
    render.render_scene("table", 0, TINY, renders)  # the cache filled
    for image in sorted((root / "images").rglob("*.webp")):
        good = image.read_bytes()
        image.write_bytes(good[:-5] + bytes([good[-5] ^ 0xFF]) + good[-4:])
        for made in (render.render_scene, render.cached_entry):
            with pytest.raises(BenchError, match=rf"{image.name} is altered \(SHA-256"):
                made("table", 0, TINY, renders)
        image.write_bytes(good)
    assert render.cached_entry("table", 0, TINY, renders) is not None


def test_a_view_that_does_not_decode_to_its_manifests_pixels_is_refused(shipped):
    root, _, renders = shipped
    manifest = json.loads((root / reference.MANIFEST).read_text())
    name = sorted(manifest["images"])[0]
    manifest["images"][name]["pixels"] = "0" * 64  # its SHA-256 kept
    (root / reference.MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(BenchError, match="does not decode to its manifest's pixels"):
        render.render_scene("table", 0, TINY, renders)


def test_other_settings_code_or_a_named_variant_render_anew(shipped, monkeypatch):
    """The set is read only for the rig it holds, under the render key of today's scene
    code and settings; otherwise (or with a variant named) the scene is rendered."""
    _, made, renders = shipped
    assert render.entry_name("table", 0, TINY, renders).startswith(reference.SUBFOLDER)
    named = RenderConfig(**{**TINY.__dict__, "variant": "scalar_rgb"})
    assert not render.entry_name("table", 0, named, renders).startswith(reference.SUBFOLDER)
    for other in (("table", 1, TINY), ("table", 0, RenderConfig(**{**TINY.__dict__, "spp": 4}))):
        assert not render.entry_name(other[0], other[1], other[2], renders).startswith("reference")
    monkeypatch.setattr(render, "code_hash", lambda modules: "edited-scenes")
    assert not render.entry_name("table", 0, TINY, renders).startswith(reference.SUBFOLDER)


def test_a_rebuilt_set_keeps_its_files_and_refuses_two_pixels_for_one_view(shipped, tmp_path):
    root, made, _ = shipped
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*.webp")}
    reference.write_reference([render.reference_input(made)], root)
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*.webp")} == before
    other = tmp_path / "other"
    shutil.copytree(made, other)
    image = cv2.imread(str(other / render.image_name(0)))
    cv2.imwrite(str(other / render.image_name(0)), 255 - image)
    with pytest.raises(BenchError, match="differs from another rig's"):
        reference.write_reference([render.reference_input(e) for e in (made, other)], root)
