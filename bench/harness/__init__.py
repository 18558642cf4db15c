"""The harness. In: the benchmark grid (scenes, seeds, policies, budgets, tasks,
protocols) and the run configuration. Out: a results folder: `runs.csv`, the stored
predictions and models, `config.json`, `vocabulary.json` and `manifest.json`.

`config` holds the run's settings; `tasks` the task registry (each task's reconstruction,
evaluation and required metrics); `predict` one unit up to its exported models, stored as
its prediction; `evaluate` scores a stored prediction into rows; `execute` runs the units
in process or on Dask; `grid` drives the whole grid resumably; `training` fits the
`learned` policy's weights.
"""
