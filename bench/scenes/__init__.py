"""Scene descriptions. In: `scenes/<name>.toml` (a scene type's documented
parameters) and a seed. Out: a renderer-independent `SceneDescription` (meshes,
materials, lights, the calibrated camera rig).

`spec` holds the data types, the registry and `load_spec`; `generators` the builders
of the scene types (a new scene type goes there); `shapes` and `textures` the numpy
primitives they are made of; `catalog` the scene types by name with every builder
registered (`build_scene` is imported from there). This package imports none of them,
and they import each other by full module path only: no import runs back into its caller.
"""
