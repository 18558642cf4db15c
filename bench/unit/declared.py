"""The package's declarations in one place: importing this module imports every module
that declares a method, a task or a metric (`DECLARED_IN`), so `package_vocabulary`
holds all of them (`bench.vocabulary` holds the registries; a method
from outside is declared by a policy module or an entry point, `bench.frontend.plugins`).
"""

from __future__ import annotations

from bench.acquisition import choosers
from bench.backend import equal_count, peers
from bench.evaluation import next_views, oracle
from bench.frontend import feedback, matchability, policies, tracks
from bench.unit import nbv, tasks
from bench.vocabulary import Vocabulary

DECLARED_IN = (
    policies,
    matchability,
    feedback,
    tracks,
    peers,
    equal_count,
    oracle,
    choosers,
    next_views,
    tasks,
    nbv,
)
"""The modules that declare the package's methods, tasks and metrics."""


def package_vocabulary() -> Vocabulary:
    """Every method, task and metric declared in this process: the package's and those
    of the policy modules loaded."""
    return Vocabulary.current()
