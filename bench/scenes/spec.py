"""Scene descriptions: renderer-independent geometry, materials, lights and the camera rig.

A scene type is declared as data in `scenes/<name>.toml` (its parameters, documented)
and built in code by a generator registered with `@generator(name)`, from an explicit
`numpy.random.Generator`. Nothing here knows about Mitsuba.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bench import ROOT, BenchError
from bench.camera import Camera

SCENES_DIR = ROOT / "scenes"


@dataclass
class Material:
    """Two-sided diffuse surface; an emitter also emits `emission` along its face normals."""

    texture: np.ndarray | None = None
    """Linear albedo, float32 HxWx3 in [0, 1]; its first row is v = 0."""
    color: tuple[float, float, float] = (0.5, 0.5, 0.5)
    """Albedo where there is no texture."""
    emission: tuple[float, float, float] | None = None
    """Radiance of an area light, or None."""


@dataclass
class Mesh:
    """A triangle mesh with per-vertex texture coordinates."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    material: Material
    motion: np.ndarray | None = None
    """Per-view vertex displacement (views, N, 3), e.g. leaves in the wind; None if static."""

    def vertices_in_view(self, view: int) -> np.ndarray:
        return self.vertices if self.motion is None else self.vertices + self.motion[view]


@dataclass
class SceneDescription:
    """Everything the renderer needs, and nothing renderer-specific."""

    name: str
    seed: int
    params: dict
    meshes: list[Mesh]
    cameras: list[Camera]
    sun: dict | None = None
    """Directional light: {'direction': (x, y, z) it travels along, 'irradiance': (r, g, b)}."""


@dataclass(frozen=True)
class SceneSpec:
    """A scene type as declared in `scenes/<name>.toml`."""

    name: str
    description: str
    params: dict = field(default_factory=dict)
    docs: dict = field(default_factory=dict)
    """One line of documentation per parameter (the comment beside it in the file)."""


Generator = Callable[
    [dict, np.random.Generator, int, int, int], tuple[list[Mesh], list[Camera], dict | None]
]
_GENERATORS: dict[str, Generator] = {}


def generator(name: str) -> Callable[[Generator], Generator]:
    """Register the builder of scene type `name`: (params, rng, width, height, views) ->
    (meshes, cameras, sun), with `views` cameras on the scene's camera path."""

    def register(fn: Generator) -> Generator:
        _GENERATORS[name] = fn
        return fn

    return register


def generator_of(name: str) -> Generator:
    """The builder registered for scene type `name`; a scene declared in `scenes/` without
    one is a `BenchError` saying where to add it."""
    if name not in _GENERATORS:
        raise BenchError(
            f"scene {name!r} is declared in {SCENES_DIR / (name + '.toml')} but no builder "
            f'is registered for it: add `@generator("{name}")` to a function in '
            "bench/scenes/generators.py (docs/extending.md)"
        )
    return _GENERATORS[name]


def scene_names() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def load_spec(name: str) -> SceneSpec:
    """Read `scenes/<name>.toml`; an unknown name is a `BenchError` listing the valid ones."""
    path = SCENES_DIR / f"{name}.toml"
    if not path.is_file():
        raise BenchError(f"unknown scene {name!r}; valid: {', '.join(scene_names())}")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise BenchError(f"cannot parse {path}: {e}") from e
    docs = {}
    for line in path.read_text().splitlines():
        key, _, comment = line.partition("#")
        if "=" in key and comment:
            docs[key.split("=")[0].strip()] = comment.strip()
    return SceneSpec(name, data.get("description", ""), dict(data.get("params", {})), docs)


def build_scene(
    spec: SceneSpec, seed: int, width: int, height: int, views: int
) -> SceneDescription:
    """Generate the scene deterministically from its parameters and seed, seen by `views`
    cameras (import it from `bench.scenes.catalog`, which registers the builders)."""
    rng = np.random.default_rng([seed, int.from_bytes(spec.name.encode()[:8], "little")])
    meshes, cameras, sun = generator_of(spec.name)(spec.params, rng, width, height, views)
    return SceneDescription(spec.name, seed, dict(spec.params), meshes, cameras, sun)
