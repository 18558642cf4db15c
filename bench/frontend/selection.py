"""A policy's selection in every view of a scene: a per-view policy view by view with a
generator seeded per view, a multi-view policy over all views with the back end's
matcher (passed in: the front end does not import the back end).

A policy sees the signals it declares (`@policy(..., reads=...)`) and no other: reading
another is refused in one line (`bench run` computes every signal, `bench select` only
the declared ones, so an undeclared read would otherwise differ between them)."""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from bench import BenchError
from bench.frontend.plugins import firewall
from bench.frontend.policies import (
    MULTIVIEW,
    POLICIES,
    PolicyConfig,
    PolicyInput,
    check_methods,
    select,
)
from bench.frontend.signals import SIGNALS, Signals
from bench.vocabulary import METHODS

BY_VIEW: dict[str, Callable] = {}
"""The multi-view policies that take a budget per view, registered where they are defined
(`bench.frontend.tracks`): (inputs, budgets, settings, match) -> each view's selection."""


def check_budgets(pools: list[int], budgets, where: str) -> None:
    """Refuse an empty front end, or a budget above every pool of `where` (every policy
    would select the whole pool): the one rule of `bench run` and `bench select`. `pools`:
    each view's candidate count."""
    largest = max(pools, default=0)
    if largest == 0:
        raise BenchError(
            f"the detector found no candidate in any view of {where}; "
            "the images are too small or too flat for it (try a larger --width/--height)"
        )
    too_big = [b for b in budgets if b > largest]
    if too_big:
        raise BenchError(
            f"budget {too_big[0]} exceeds every candidate pool of {where} "
            f"(the largest has {largest}); every policy would select the whole pool. "
            f"Use budgets up to {largest}"
        )


class DeclaredSignals:
    """A view's signals as a policy sees them: those it declared, and no other."""

    def __init__(self, signals: Signals, policy: str, reads: tuple[str, ...]):
        self._signals, self._policy, self._reads = signals, policy, reads

    def __getattr__(self, name: str):
        if name in SIGNALS and name not in self._reads:
            raise BenchError(
                f"policy {self._policy} reads the signal {name!r}, which it did not declare; "
                f"add it to @policy(..., reads=...) (declared: {', '.join(self._reads) or 'none'})"
            )
        return getattr(self._signals, name)


def policy_rng(seed: int, policy: str, budget: int, view: int) -> np.random.Generator:
    """The generator of one view of a unit of work, derived from the run's seed."""
    return np.random.default_rng([seed, zlib.crc32(policy.encode()), budget, view])


def select_views(
    policy: str,
    inputs: list[PolicyInput],
    budget: int | list[int],
    seed: int,
    cfg: PolicyConfig,
    match,
) -> tuple[list[np.ndarray], list[dict]]:
    """Every view's selection and a multi-view policy's rounds (none for a per-view
    policy); the policy runs behind the ground-truth firewall
    (`bench.frontend.plugins.firewall`) and reads only the signals it declares. `budget`:
    one for every view, or one per view (`by_view`)."""
    reads = METHODS[check_methods([policy])[0]].reads
    inputs = [replace(i, signals=DeclaredSignals(i.signals, policy, reads)) for i in inputs]
    if isinstance(budget, list):
        return by_view(policy, inputs, budget, seed, cfg, match), []
    if policy in MULTIVIEW:
        with firewall():
            return MULTIVIEW[policy](inputs, budget, cfg, match)
    if policy not in POLICIES:
        raise BenchError(f"{policy} is not a selection policy (a reference or a peer)")
    rngs = [policy_rng(seed, policy, budget, i.view.index) for i in inputs]
    with firewall():
        return [select(policy, i, budget, r, cfg) for i, r in zip(inputs, rngs)], []


def by_view(policy, inputs, budgets: list[int], seed: int, cfg, match) -> list[np.ndarray]:
    """Each view's selection at its own budget, at most its pool (a view at 0 selects
    nothing): a per-view policy view by view, a multi-view one of `BY_VIEW` at once (the
    equal-count kind's peer counts, `bench.backend.equal_count`)."""
    budgets = [min(int(n), len(i.candidates)) for i, n in zip(inputs, budgets)]
    if policy in BY_VIEW:
        with firewall():
            return BY_VIEW[policy](inputs, budgets, cfg, match)
    out = []
    for inp, n in zip(inputs, budgets):
        if n == 0:
            out.append(np.zeros(0, np.int64))
            continue
        rng = policy_rng(seed, policy, n, inp.view.index)
        with firewall():
            out.append(select(policy, inp, n, rng, cfg))
    return out
