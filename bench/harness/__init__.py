"""The harness. In: the benchmark grid (scenes, seeds, policies, budgets, tasks,
protocols) and the run configuration. Out: a results folder: `runs.csv`, the stored
predictions and models, `config.json`, `vocabulary.json` and `manifest.json`.

What decides one row is the unit's (`bench.unit`); the harness orchestrates: `keys`
computes the rows' keys (the prediction and evaluation hashes) once; `execute` runs the
units in process or on Dask; `grid` drives the whole grid resumably; `manifest` records a
folder's provenance; `select` runs a policy on photographs; `training` and `matchability`
fit the `learned` policy's weights and the selection models.
"""
