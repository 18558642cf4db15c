"""Evaluation: the only stage that reads ground truth. In: a render entry's
ground-truth layers, the candidate pools, the selections and the back end's result.
Out: one run's metrics (formulas in `metrics`).

`layers` reads the truth layers; `metrics` builds the scene's ground-truth structures and
computes every metric (a new metric goes there).
"""
