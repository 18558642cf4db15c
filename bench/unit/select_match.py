"""One path from a scene's views to a method's verified matches, for every caller: the
policy selects B per view (`bench.frontend.selection`: a multi-view policy with the back
end's matcher), then the back end matches and verifies the selection (with the method's
own matcher where it names one). The grid (`bench.unit.predict`), the next-views task
(`bench.unit.nbv`) and `bench select` (`bench.harness.select`) all run through it."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from bench.backend.matching import PairMatches, match_and_verify, matcher
from bench.camera import Camera
from bench.frontend.features import Candidates
from bench.frontend.policies import PolicyInput
from bench.frontend.selection import select_views
from bench.frontend.signals import Signals
from bench.frontend.views import View
from bench.unit.config import RunConfig
from bench.vocabulary import METHODS, Unit


def select(
    views: list[View],
    pools: list[Candidates],
    signals: list[Signals],
    unit: Unit,
    cfg: RunConfig,
    budget: list[int] | None = None,
) -> tuple[list[np.ndarray], list[dict], float]:
    """Each view's selection by the unit's method at its budget (or at `budget`, one per
    view, `bench.frontend.selection.by_view`) and seed, a multi-view policy's rounds, and
    the seconds it took; the policy is told the unit's scene (`PolicyInput.scene`)."""
    t = time.perf_counter()
    inputs = [PolicyInput(v, c, s, unit.scene) for v, c, s in zip(views, pools, signals)]
    match = matcher([v.camera for v in views], pools, cfg.backend, cfg.detector.detector)
    own = cfg.policy_config(unit.method)
    selections, rounds = select_views(
        unit.method, inputs, unit.budget if budget is None else budget, unit.seed, own, match
    )
    return selections, rounds, time.perf_counter() - t


def match(
    cams: list[Camera],
    pools: list[Candidates],
    selections: list[np.ndarray],
    method: str,
    cfg: RunConfig,
) -> tuple[list[PairMatches], dict[str, float]]:
    """The selection's verified pairs and the seconds of matching and verifying."""
    backend = cfg.backend
    if METHODS[method].matcher:
        backend = replace(backend, matcher=METHODS[method].matcher)
    xy = [c.xy[s] for c, s in zip(pools, selections)]
    desc = [c.descriptors[s] for c, s in zip(pools, selections)]
    return match_and_verify(cams, xy, desc, backend, cfg.detector.detector)
