"""A policy module for the entry-point test (`bench.policies` group)."""

import numpy as np

from bench.frontend.policies import policy


@policy("first-b")
def first_b(inp, budget, rng, cfg):
    """The first B candidates."""
    return np.arange(min(budget, len(inp.candidates)))
