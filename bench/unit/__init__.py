"""The unit: what decides a row. In: one selection of one method on one scene (or one
dataset's bag) at one budget, with the run's settings (`config`). Out: its prediction
(the selection, matched and verified once per geometry, and each job's reconstruction),
stored in its folder, and the rows of the tasks scored on it.

`config` holds the settings that decide the rows; `methods` the kinds of method (how a
unit of each kind is predicted and scored; what its budget means is declared with the kind,
`bench.vocabulary.budget_means`); `declared` the
modules that declare the package's methods; `predict` one unit up to its exported models;
`select_match` a selection matched and verified; `equal` the equal-count peers;
`tasks` the task registry (each task's reconstruction, evaluation and required
metrics); `nbv` the next-views task; `bags` a dataset's bags; `evaluate` scores a stored
prediction into rows. Nothing here hashes code or settings: the harness computes a
row's keys once (`bench.harness.keys`) and hands them in (`predict.Keys`).
"""
