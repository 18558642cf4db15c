"""Candidate pools: the registry (`registry`) and the built-in pools, one module each,
registered on import."""

from bench.frontend.pools import opencv  # noqa: F401  (registers them: the default first)

# isort: split
from bench.frontend.pools import aliked, disk, xfeat  # noqa: F401
from bench.frontend.pools.registry import (  # noqa: F401
    ORIGIN,
    POOLS,
    RATIO,
    Pool,
    PoolSpec,
    get_pool,
    register_pool,
    strongest_first,
)
