"""The report. In: a results folder (`runs.csv`, `vocabulary.json`, the exported
models) and the render cache's images for Figure 2. Out: the tables, the figures and the
published snapshot.

`stats` holds the intervals and paired differences, `tables` the tables,
`figures` the figures, `write` writes them all (`bench plot`) and publishes a folder
(`bench publish`). Nothing here imports a stage that renders, selects, reconstructs or
scores (`tests/test_layout.py`).
"""
