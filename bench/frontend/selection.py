"""A policy's selection in every view of a scene: the registry's policies view by view
with a generator seeded per view, or the feedback loop over all views with the back
end's matcher (passed in: the front end does not import the back end).

A policy sees the signals it declares (`@policy(..., reads=...)`) and no other: reading
another is refused in one line (`bench run` computes every signal, `bench select` only
the declared ones, so an undeclared read would otherwise differ between them)."""

from __future__ import annotations

import zlib
from dataclasses import replace

import numpy as np

from bench import BenchError
from bench.frontend import feedback, plugins
from bench.frontend.feedback import Match
from bench.frontend.policies import PolicyConfig, PolicyInput, check_methods, select
from bench.frontend.signals import SIGNALS, Signals
from bench.vocabulary import METHODS


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
    budget: int,
    seed: int,
    cfg: PolicyConfig,
    match: Match,
) -> tuple[list[np.ndarray], list[dict]]:
    """Every view's selection (outside policies registered first), and the feedback
    loop's rounds (none for other policies); the policy runs behind the ground-truth
    firewall (`bench.frontend.plugins.firewall`) and reads only the signals it declares."""
    plugins.load(cfg.modules)
    reads = METHODS[check_methods([policy])[0]].reads
    inputs = [replace(i, signals=DeclaredSignals(i.signals, policy, reads)) for i in inputs]
    if policy == feedback.NAME:
        with plugins.firewall():
            return feedback.feedback_select(inputs, budget, cfg, match)
    rngs = [policy_rng(seed, policy, budget, i.view.index) for i in inputs]
    with plugins.firewall():
        return [select(policy, i, budget, r, cfg) for i, r in zip(inputs, rngs)], []
