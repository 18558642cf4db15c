"""The registry of candidate pools: the detector behind every view's pool, each declared
by a small module of its own (`register_pool`), as a policy is: how it detects
(keypoints, scores, descriptors, at what image size), its standard matcher, and its
near-duplicate distance.

Built in: `sift`, `orb` and `akaze` (`bench.frontend.pools.opencv`), `aliked` and `disk`
with LightGlue, `xfeat` with LighterGlue (the `learned` extra: their weights ship in
their packages, nothing is downloaded). A user's own detector comes in a file given to
`bench run --pool-module` (docs/extending.md).

A grid names a pool with the matcher its selections are matched with (`PoolSpec`):
`aliked` is ALIKED with its standard matcher (LightGlue), `aliked+ratio` the same pool
with ratio matching, so that a table can tell the detector from the matcher.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import import_module
from typing import NamedTuple

import numpy as np

from bench import BenchError
from bench.codehash import versions
from bench.files import checksum

RATIO = "ratio"
"""Mutual nearest neighbours passing Lowe's ratio test: every pool's matcher
(`bench.backend.matching`)."""
INSTALL = "LEARNED=1 bash scripts/setup.sh"

Side = tuple[np.ndarray, np.ndarray, tuple[int, int]]
"""One view's side of a learned matcher: xy (COLMAP's convention), descriptors, (width,
height) of the image."""


@dataclass(frozen=True)
class Pool:
    """A detector whose keypoints are every view's candidate pool."""

    name: str
    detect: Callable
    """(RGB uint8 image, `DetectorConfig`) -> xy (COLMAP's convention), size, angle,
    response, descriptors of the view's pool: at most the configured number of
    candidates (`max_features`, a learned pool's `learned_keypoints`)."""
    points: Callable
    """(gray uint8 image, `DetectorConfig`) -> keypoint locations alone (re-detection
    under perturbations, `bench.frontend.signals.repeatability_redetect`)."""
    duplicate_distance: float
    """tau: the descriptor distance within which two candidates of a view are near
    duplicates (`bench.frontend.signals`)."""
    matcher: str = RATIO
    """Its standard matcher: `ratio`, or the name of its learned one (`match`)."""
    match: Callable[[Side, Side], np.ndarray] | None = None
    """The learned matcher: two sides -> (M, 2) index pairs, by the first index."""
    binary: bool = False
    """Descriptors are bit strings (Hamming distance), not unit float vectors."""
    packages: tuple[str, ...] = ()
    """The distributions its pool and matcher read: their versions decide its rows, and
    without them asking for it is one line (`require`)."""
    label: str = field(default="", compare=False)
    """Its name in a peer's label (empty: its name)."""

    @property
    def matchers(self) -> tuple[str, ...]:
        """The matchers its selections can be matched with."""
        return (RATIO,) if self.matcher == RATIO else (self.matcher, RATIO)

    def identity(self) -> dict[str, str]:
        """What decides its pool beyond the package's code: its packages' versions and,
        for a pool from outside the package (`ORIGIN`), its module file's content."""
        self.require()
        out = versions(self.packages)
        return out | ({"pool module": checksum(ORIGIN[self.name])} if self.name in ORIGIN else {})

    def require(self) -> None:
        """Refuse, in one line, a pool whose packages are not installed."""
        for package in self.packages:
            try:
                import_module(package.replace("-", "_"))
            except ImportError as e:
                raise BenchError(
                    f"the {self.name} pool needs the `learned` extra ({e.name} is missing): "
                    f"{INSTALL}"
                ) from None


POOLS: dict[str, Pool] = {}
"""Every declared pool, by name."""
ORIGIN: dict[str, str] = {}
"""The source file of every pool registered from outside the package."""


def register_pool(pool: Pool) -> Pool:
    """Declare a pool under a name no other pool has (a name without `+` or `:`)."""
    if pool.name in POOLS:
        raise BenchError(f"pool name {pool.name!r} is taken; give the pool another name")
    if not pool.name or any(c in pool.name for c in "+:,@ "):
        raise BenchError(f"pool name {pool.name!r}: use letters, digits, '-' or '_'")
    POOLS[pool.name] = pool
    return pool


def get_pool(name: str) -> Pool:
    """The pool declared as `name`, or one line naming the valid ones."""
    if name not in POOLS:
        raise BenchError(f"unknown pool {name!r}; valid: {', '.join(POOLS)}")
    return POOLS[name]


class PoolSpec(NamedTuple):
    """A pool of a grid: its detector and the matcher its selections are matched with."""

    pool: str
    matcher: str

    @classmethod
    def parse(cls, text: str) -> PoolSpec:
        """`<pool>` (its standard matcher) or `<pool>+<matcher>`; one line if neither."""
        name, _, matcher = text.strip().partition("+")
        pool = get_pool(name)
        matcher = matcher or pool.matcher
        if matcher not in pool.matchers:
            raise BenchError(
                f"pool {text!r}: {name} can be matched with {' or '.join(pool.matchers)}, "
                f"not {matcher}"
            )
        return cls(name, matcher)

    def __str__(self) -> str:
        standard = POOLS[self.pool].matcher if self.pool in POOLS else RATIO
        return self.pool if self.matcher == standard else f"{self.pool}+{self.matcher}"


def strongest_first(values: np.ndarray) -> np.ndarray:
    """Indices by descending value (a response, a score); ties by index, so selection is
    deterministic."""
    return np.lexsort((np.arange(len(values)), -np.asarray(values)))
