"""Rendered-scene benchmark of keypoint selection policies for 3D reconstruction.

The subpackages are the stages of the data flow, in the order below; a stage imports only
the stages before it and the shared modules of this package (`camera`, `files`, `console`,
`vocabulary`, `results`, ...; `tests/test_layout.py` holds the order, `STAGES`, and checks
it: not here, where every code key, the render key's too, would take it).

`scenes` describes scenes, `render` path-traces them into cached render entries,
`frontend` detects candidates, computes their signals and selects features (policies),
`backend` matches, verifies and reconstructs with COLMAP, `acquisition` holds the view
choosers of the next-views task, `evaluation` scores against ground truth (the only stage
that reads it), `unit` decides one row (a unit's prediction and its scores), `harness`
runs the grid into a results folder (the units' keys, predictions, then scores),
`report` makes the tables and figures from a results folder alone, and `cli` is the
command line.
"""

from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
"""Repository root: holds `scenes/`, the default `renders/` and the published results."""

DISTRIBUTION = "kpbudget-bench"
"""The distribution's name on a package index (the import package is `bench`)."""
try:
    __version__ = version(DISTRIBUTION)
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0+unknown"


class BenchError(Exception):
    """A user-facing error: the CLI prints its message on one line and exits non-zero."""


class MethodFailed(BenchError):
    """A method (a policy, a view chooser) raised or broke its contract: the method failed,
    not the input. Says what and where in its code (`file:line`); a grid records it in the
    unit's rows and goes on (`bench.harness.execute`), naming the tasks whose rows it
    fails (`tasks`, set where it is caught)."""

    def __init__(self, name: str, what: str, where: str, message: str):
        super().__init__(message)
        self.policy, self.what, self.where = name, what, where
        self.tasks: tuple[str, ...] = ()
