"""Stage 1, scene descriptions. In: `scenes/<name>.toml` (a scene type's documented
parameters) and a seed. Out: a renderer-independent `SceneDescription` (meshes,
materials, lights, the calibrated camera rig).

`spec` holds the data types, the registry and `build_scene`; `generators` the builders
of the scene types (a new scene type goes there); `shapes` and `textures` the numpy
primitives they are made of.
"""

from bench.scenes import generators  # noqa: F401  (registers the scene builders)
from bench.scenes.spec import SceneDescription, SceneSpec, build_scene, load_spec, scene_names

__all__ = ["SceneDescription", "SceneSpec", "build_scene", "load_spec", "scene_names"]
