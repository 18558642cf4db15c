"""Each scene type has the property the benchmark tests it for."""

from __future__ import annotations

import numpy as np
import pytest

from bench.evaluation.layers import read_layers
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.pools import POOLS
from bench.frontend.signals import same_view_neighbours
from bench.frontend.views import load_views
from bench.scenes.catalog import build_scene, generator_of, load_spec, scene_names
from tests.conftest import rig


def test_every_declared_scene_has_its_parameters_documented_and_a_builder():
    """The paper's four scene types and any scene added to `scenes/`: each documented and
    built (a new scene is picked up here and by every test parametrized by scene_names)."""
    assert {"corridor", "facade", "table", "vegetation"} <= set(scene_names())
    for name in scene_names():
        spec = load_spec(name)
        assert spec.description and spec.params
        assert set(spec.docs) == set(spec.params), f"{name}: every parameter is documented"
        assert generator_of(name)


def test_a_scene_without_a_builder_is_one_clear_line(tmp_path, monkeypatch):
    from bench import BenchError
    from bench.scenes import spec

    (tmp_path / "dunes.toml").write_text(
        'description = "sand"\n[params]\nheight = 2 # dune height\n'
    )
    monkeypatch.setattr(spec, "SCENES_DIR", tmp_path)
    with pytest.raises(BenchError, match="no builder is registered for it: add `@generator"):
        build_scene(load_spec("dunes"), 0, 64, 48, 3)


@pytest.mark.parametrize("scene", scene_names())
def test_median_camera_to_surface_distance_is_5_to_10_units(tiny_entry, scene):
    entry = tiny_entry(scene)
    layers = read_layers(entry)
    ranges = np.concatenate([gt.range.ravel() for gt in layers])
    assert 5 <= np.nanmedian(ranges) <= 10


def _median_parallax_deg(entry) -> float:
    """Median angle between consecutive cameras' rays to the surface points seen in the
    central fifth of each image (where the corridor's rig puts its vanishing point)."""
    cams = rig(entry)
    angles = []
    for v in range(5):
        X = np.load(entry / f"gt_{v:02d}.npz")["position"]
        h, w = X.shape[:2]
        X = X[2 * h // 5 : 3 * h // 5, 2 * w // 5 : 3 * w // 5].reshape(-1, 3)
        X = X[np.isfinite(X).all(1)]
        a, b = cams[v].center - X, cams[v + 1].center - X
        cos = (a * b).sum(1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return float(np.median(np.concatenate(angles)))


def test_points_near_the_corridors_vanishing_point_have_little_parallax(tiny_entry):
    """The corridor's property: what its cameras look at (the far end) barely moves
    between views, unlike the table's centre (measured at 2.8 against 11.7 degrees)."""
    corridor, table = (
        _median_parallax_deg(tiny_entry("corridor")),
        _median_parallax_deg(tiny_entry("table")),
    )
    assert corridor < 0.5 * table, (corridor, table)


@pytest.fixture(scope="module")
def sift_entries(medium_entry):
    """Facade and table at a size where SIFT has something to find."""
    return {s: medium_entry(s) for s in ("facade", "table")}


def _near_duplicate_fraction(entry) -> float:
    fractions = []
    for view in load_views(entry)[:3]:
        d1 = same_view_neighbours(detect(view, DetectorConfig()), 0.0)[0]
        fractions.append(np.mean(d1 < POOLS["sift"].duplicate_distance))
    return float(np.mean(fractions))


def test_facade_descriptors_have_more_near_duplicates_than_table(sift_entries):
    facade, table = (_near_duplicate_fraction(sift_entries[s]) for s in ("facade", "table"))
    assert facade > table + 0.15, (facade, table)


def test_wind_moves_leaves_between_views_and_not_the_ground():
    spec = load_spec("vegetation")
    windy = build_scene(spec, 0, 64, 48, 6)
    leaves = [m for m in windy.meshes if m.name.startswith("leaves")]
    assert leaves and all(m.motion is not None for m in leaves)
    moved = np.linalg.norm(leaves[0].vertices_in_view(1) - leaves[0].vertices_in_view(0), axis=1)
    assert np.median(moved) > 0.5 * spec.params["wind"]
    for m in windy.meshes:
        if not m.name.startswith("leaves"):
            assert np.array_equal(m.vertices_in_view(0), m.vertices_in_view(5)), m.name
    still = build_scene(
        type(spec)(spec.name, spec.description, {**spec.params, "wind": 0.0}), 0, 64, 48, 6
    )
    for m in still.meshes:
        assert np.array_equal(m.vertices_in_view(0), m.vertices_in_view(3))
