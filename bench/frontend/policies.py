"""Feature selection policies (paper, section 4.2): one registry, one contract.

A policy receives a `PolicyInput` (the view's image and calibration, its candidates and
their signals: no ground truth can reach it) with a budget B and a seeded generator, and
returns exactly min(B, N) distinct candidate indices. Adding a policy is one decorated
function.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench import BenchError
from bench.frontend.features import Candidates
from bench.frontend.signals import Signals
from bench.frontend.views import View


@dataclass(frozen=True)
class PolicyInput:
    """Everything a policy may look at."""

    view: View
    candidates: Candidates
    signals: Signals


@dataclass(frozen=True)
class PolicyConfig:
    """Settings of the selection policies."""

    weights: tuple[float, float, float, float, float] = (0.28, 0.27, 0.22, 0.19, 0.20)
    """Adaptive score weights for texture, repeatability, distinctiveness, parallax and
    ambiguity: s = w_t t + w_r r + w_q q + w_p p - w_a a (the paper's values)."""
    tiles: tuple[int, int] = (8, 6)
    """Columns x rows of the tile grid used by the grid policy and the adaptive tile cap."""
    cap_factor: float = 2.0
    """Adaptive soft cap: a tile may hold at most cap_factor x B / (non-empty tiles)
    selections, until the cap must grow to fill the budget."""

    def validate(self) -> PolicyConfig:
        if len(self.weights) != 5 or not all(
            isinstance(w, int | float) and math.isfinite(w) for w in self.weights
        ):
            raise BenchError(f"weights must be five numbers (t, r, q, p, a), got {self.weights!r}")
        if min(self.tiles) <= 0 or self.cap_factor <= 0:
            raise BenchError("tiles and cap_factor must be positive")
        return self


Policy = Callable[[PolicyInput, int, np.random.Generator, PolicyConfig], np.ndarray]
POLICIES: dict[str, Policy] = {}
SIGNALS_USED: dict[str, tuple[str, ...]] = {}
"""The signals each policy reads, so its front-end cost can be reported honestly."""


def policy(name: str, signals: tuple[str, ...] = ()) -> Callable[[Policy], Policy]:
    def register(fn: Policy) -> Policy:
        POLICIES[name], SIGNALS_USED[name] = fn, signals
        return fn

    return register


def check_policies(names) -> list[str]:
    unknown = [n for n in names if n not in POLICIES]
    if unknown:
        raise BenchError(f"unknown policy {unknown[0]!r}; valid: {', '.join(POLICIES)}")
    return list(names)


def select(
    name: str,
    inp: PolicyInput,
    budget: int,
    rng: np.random.Generator,
    cfg: PolicyConfig = PolicyConfig(),
) -> np.ndarray:
    """Run a policy and check its contract: min(B, N) distinct valid indices (`all`, the
    whole pool, takes no budget)."""
    check_policies([name])
    if budget <= 0 and name != "all":
        raise BenchError(f"budget must be positive, got {budget}")
    idx = np.asarray(POLICIES[name](inp, budget, rng, cfg), dtype=np.int64)
    n = len(inp.candidates)
    want = n if name == "all" else min(budget, n)
    if (
        len(idx) != want
        or len(np.unique(idx)) != len(idx)
        or (len(idx) and (idx.min() < 0 or idx.max() >= n))
    ):
        raise RuntimeError(f"policy {name} broke its contract ({len(idx)} indices for {want})")
    return idx


def tile_of(xy: np.ndarray, width: int, height: int, tiles: tuple[int, int]) -> np.ndarray:
    """Index of the tile (row-major, tiles = columns x rows) holding each point."""
    cx = np.clip((xy[:, 0] / width * tiles[0]).astype(int), 0, tiles[0] - 1)
    cy = np.clip((xy[:, 1] / height * tiles[1]).astype(int), 0, tiles[1] - 1)
    return cy * tiles[0] + cx


def adaptive_score(s: Signals, w) -> np.ndarray:
    wt, wr, wq, wp, wa = w
    return (
        wt * s.texture
        + wr * s.repeatability
        + wq * s.distinctiveness
        + wp * s.parallax
        - wa * s.ambiguity
    )


def _order(score: np.ndarray) -> np.ndarray:
    """Indices by descending score; ties broken by index, so selection is deterministic."""
    return np.lexsort((np.arange(len(score)), -score))


@policy("random")
def random_policy(inp, budget, rng, cfg):
    """A uniform random subset."""
    return rng.choice(len(inp.candidates), size=min(budget, len(inp.candidates)), replace=False)


@policy("texture", ("texture",))
def texture_policy(inp, budget, rng, cfg):
    """The B candidates of highest texture."""
    return _order(inp.signals.texture)[:budget]


@policy("grid", ("texture",))
def grid_policy(inp, budget, rng, cfg):
    """Equal quota per tile, best texture first inside each tile; quota a tile cannot use
    goes to the others: round k takes every tile's k-th best candidate, ordered by texture."""
    cam = inp.view.camera
    tile = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
    order = _order(inp.signals.texture)
    rank = np.empty(len(order), int)
    for t in np.unique(tile):
        members = order[tile[order] == t]
        rank[members] = np.arange(len(members))
    by_round = np.lexsort((np.arange(len(order)), -inp.signals.texture, rank))
    return by_round[:budget]


@policy("adaptive", ("texture", "repeatability", "distinctiveness", "ambiguity", "parallax"))
def adaptive_policy(inp, budget, rng, cfg):
    """Greedy by score s under a soft per-tile cap: at most ceil(cap_factor * B / T) per
    tile (T = tiles holding candidates); only if the pool cannot fill B under that cap is
    it raised, one step at a time, until the budget is met."""
    cam = inp.view.camera
    tile = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
    order = _order(adaptive_score(inp.signals, cfg.weights))
    want = min(budget, len(order))
    cap = math.ceil(cfg.cap_factor * budget / max(len(np.unique(tile)), 1))
    picked: list[int] = []
    chosen = np.zeros(len(order), bool)
    count = np.zeros(cfg.tiles[0] * cfg.tiles[1], int)
    while len(picked) < want:
        for i in order:
            if len(picked) == want:
                break
            if not chosen[i] and count[tile[i]] < cap:
                chosen[i] = True
                count[tile[i]] += 1
                picked.append(i)
        cap += 1
    return np.array(picked, dtype=np.int64)


@policy("all")
def all_policy(inp, budget, rng, cfg):
    """The whole pool, whatever the budget: the reference row."""
    return np.arange(len(inp.candidates))
