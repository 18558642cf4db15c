"""A policy's selection in every view of a scene: the registry's policies view by view
with a generator seeded per view, or the feedback loop over all views with the back
end's matcher (passed in: the front end does not import the back end)."""

from __future__ import annotations

import zlib

import numpy as np

from bench.frontend import feedback, plugins
from bench.frontend.feedback import Match
from bench.frontend.policies import PolicyConfig, PolicyInput, select


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
    firewall (`bench.frontend.plugins.firewall`)."""
    if policy == feedback.NAME:
        with plugins.firewall():
            return feedback.feedback_select(inputs, budget, cfg, match)
    plugins.load(cfg.modules)
    rngs = [policy_rng(seed, policy, budget, i.view.index) for i in inputs]
    with plugins.firewall():
        return [select(policy, i, budget, r, cfg) for i, r in zip(inputs, rngs)], []
