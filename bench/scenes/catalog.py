"""The scene types by name, with every builder in `generators` registered: import
`build_scene` and the lookups from here (the registry itself lives in `spec`, which the
builders import; importing `generators` from here, not from the package, keeps the imports
one-way)."""

from __future__ import annotations

from bench.scenes.generators import path_positions  # importing it registers every builder
from bench.scenes.spec import (
    _GENERATORS,
    Generator,
    build_scene,
    generator_of,
    load_spec,
    scene_names,
)

__all__ = [
    "build_scene",
    "generator_functions",
    "generator_of",
    "load_spec",
    "path_positions",
    "scene_names",
]


def generator_functions() -> list[Generator]:
    """The builders of every scene type registered."""
    return list(_GENERATORS.values())
