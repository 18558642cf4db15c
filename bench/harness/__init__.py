"""Stage 6, the harness. In: the benchmark grid (scenes, seeds, policies, budgets, tasks,
protocols) and the run configuration. Out: `runs.csv`, the tables, figures and manifest.

`pipeline` is one unit of work end to end (render entry -> rows of metrics); `execute`
runs the units in process or on Dask; `grid` drives the whole grid resumably; `runs` is
the contract of `runs.csv`; `stats`, `tables` and `figures` make the report from
`runs.csv` alone (`report`); `cli` is the `bench` command line.
"""
