"""Stage 6, the harness. In: the benchmark grid (scenes, seeds, policies, budgets) and
the run configuration. Out: `runs.csv`, the tables, figures and manifest.

`pipeline` is one run end to end (render entry -> row of metrics); `grid` runs the whole
grid resumably; `report` makes tables and figures from `runs.csv` alone; `cli` is the
`bench` command line.
"""
