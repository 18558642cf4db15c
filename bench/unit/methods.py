"""One runner per kind of method (`bench.vocabulary.KINDS`): how a unit of the kind is
predicted and stored (`bench.unit.predict`), how its stored prediction is read back for
scoring (`bench.unit.evaluate`), and whether `bench select` can run it on photographs.
Every dispatch on a method goes through its declared kind (`runner`): no module compares
a method's name.

The package's methods are declared by the modules of `bench.unit.declared`; a method
from outside is declared by a policy module or an entry point (`bench.frontend.plugins`).
A package that brings a new kind of method declares it (`bench.vocabulary.declare_kind`)
and registers its runner here (`register_kind`). The view choosers and the view oracle
pick views, one at a time, and score their own units (the nbv task, `bench.unit.nbv`).

What a row's budget (B) means depends on its method's kind, and is said once, where the
kind is declared (`declare_kind(..., budget=)`, `bench.vocabulary.budget_means`): a
per-view keypoint budget; for a whole-pool method (`all`, `colmap`) 0, the pool; for an
equal-count method the budget of its peer, each view keeping the peer's own count.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from bench import BenchError
from bench.acquisition import choosers
from bench.backend.equal_count import EQUAL_COUNT
from bench.evaluation import next_views
from bench.unit import nbv
from bench.unit.declared import package_vocabulary
from bench.unit.equal import equal_shared, store_equal
from bench.unit.evaluate import Shared, evaluate, own_pipeline_shared, selection_shared
from bench.unit.predict import (
    Store,
    oracle_selection,
    policy_selection,
    store_own_pipeline,
    store_selection,
)
from bench.vocabulary import (
    GROUND_TRUTH,
    KINDS,
    METHODS,
    MULTI_VIEW,
    OWN_PIPELINE,
    PER_VIEW,
    TRACKS_PEER,
)


@dataclass(frozen=True)
class KindRunner:
    """How the units of one kind of method run."""

    store: Store
    """Compute and store a unit's prediction (`bench.unit.predict.predict`)."""
    read: Shared | None = None
    """Read it back for scoring (`bench.unit.evaluate.evaluate`); None where `score`
    reads it itself."""
    photos: bool = False
    """Whether `bench select` runs it on photographs (it needs neither ground truth nor a
    pipeline of its own)."""
    score: Callable[..., list[dict]] = evaluate
    """(scene, unit, jobs, settings, workspace, `read`) -> the unit's rows, from its stored
    prediction: `bench.unit.evaluate.evaluate`, or the kind's own."""


KIND_RUNNERS: dict[str, KindRunner] = {}


def register_kind(kind: str, runner: KindRunner) -> None:
    """The runner of a declared kind (one per kind)."""
    if kind not in KINDS:
        raise BenchError(f"kind {kind!r} is not declared (bench.vocabulary.declare_kind)")
    if kind in KIND_RUNNERS:
        raise BenchError(f"kind {kind!r} has a runner already")
    KIND_RUNNERS[kind] = runner


def runner(method: str) -> KindRunner:
    """The runner of a declared method's kind (every method of the package is declared:
    `bench.unit.declared`)."""
    if method not in METHODS:
        valid = ", ".join(package_vocabulary().methods)
        raise BenchError(f"unknown method {method!r}; valid: {valid}")
    return KIND_RUNNERS[METHODS[method].kind]


register_kind(PER_VIEW, KindRunner(store_selection(policy_selection), selection_shared, True))
register_kind(MULTI_VIEW, KindRunner(store_selection(policy_selection), selection_shared, True))
register_kind(GROUND_TRUTH, KindRunner(store_selection(oracle_selection), selection_shared))
register_kind(OWN_PIPELINE, KindRunner(store_own_pipeline, own_pipeline_shared))
register_kind(TRACKS_PEER, KindRunner(store_own_pipeline, own_pipeline_shared))
register_kind(EQUAL_COUNT, KindRunner(store_equal, equal_shared))
register_kind(
    choosers.CHOOSER, KindRunner(nbv.store_trajectory(nbv.chooser_pick), score=nbv.nbv_rows)
)
register_kind(
    next_views.VIEW_ORACLE, KindRunner(nbv.store_trajectory(nbv.oracle_pick), score=nbv.nbv_rows)
)
