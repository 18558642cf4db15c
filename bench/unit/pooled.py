"""The pools of a grid (`bench run --pools`): which of its methods run on which pool, and
under which name.

A pool of a grid is a detector with the matcher its selections are matched with
(`bench.frontend.pools.PoolSpec`: `aliked`, `aliked+ratio`). The run's own pool is its
settings' (`detector.detector` with `backend.matcher`: SIFT with ratio matching by
default); its rows keep their methods' names. On another pool:

* a method that selects from the pool (a per-view or multi-view policy) runs as
  `<method>:<pool>` (`octave-scale:aliked`, `track-first:aliked+ratio`), declared here
  with the pool's detector and matcher, its selection function and settings its own
  method's (its own settings are set under its own name, `--set octave-scale:aliked.x=`);
* a method bound to one detector (a pool's own top-B, `aliked-b`) runs on the pools of its
  detector: under its name with its own matcher (and on the run's own pool), else as
  `<method>:<pool>`;
* a method of another kind runs once, as in a grid without pools: the stock-COLMAP
  peers extract keypoints of their own (their rows name no pool), the oracle and a policy
  at a peer's count select from the run's own pool.

Each pool but SIFT has its own top-B as its peer, `<pool>-b` (`pool_peer`: the pool's B
highest-scoring keypoints, what a user of hloc keeps at a budget, matched with the pool's
standard matcher whatever `backend.matcher` says, verified, triangulated and mapped by the
policies' back end); a grid runs the peer of each of its pools (SIFT's is stock COLMAP's,
`colmap-b`, which extracts its own).

A method that cannot run on a pool of the grid (a detector's own top-B on another
detector, a kind that does not select from a pool) is said once (`placement`), never
dropped in silence. Rows carry their pool and matcher (`row_pool`).
"""

from __future__ import annotations

from dataclasses import replace

from bench import BenchError
from bench.frontend import plugins
from bench.frontend.policies import MULTIVIEW, POLICIES, register_policy, response_policy
from bench.frontend.pools import POOLS, RATIO, PoolSpec
from bench.vocabulary import (
    METHODS,
    MULTI_VIEW,
    OWN_PIPELINE,
    PER_VIEW,
    SETTINGS,
    TRACKS_PEER,
    Method,
    declare_method,
)

SEPARATOR = ":"
POOLED_KINDS = (PER_VIEW, MULTI_VIEW)
"""The kinds whose methods select from a pool, so run on any."""


MATCHER_LABELS = {RATIO: "ratio test", "lightglue": "LightGlue", "lighterglue": "LighterGlue"}


def pool_peer(pool: str) -> str | None:
    """`<pool>-b`, the pool's own top-B (module docstring), declared once; None for a pool
    matched by the ratio test alone (SIFT, ORB, AKAZE: their peers are stock COLMAP's)."""
    p, name = POOLS[pool], f"{pool}-b"
    if p.matcher == RATIO:
        return None
    if name not in METHODS:
        label = f"{p.label or pool} top-B + {MATCHER_LABELS.get(p.matcher, p.matcher)} (peer)"
        register_policy(Method(name, label, "peer", pool=pool, matcher=p.matcher), response_policy)
    return name


for _pool in tuple(POOLS):
    pool_peer(_pool)


def own_spec(run) -> PoolSpec:
    """The run's own pool: its detector with its matcher (`RunConfig`)."""
    return PoolSpec(run.detector.detector, run.backend.matcher)


def pooled_name(method: str, spec: PoolSpec) -> str:
    return f"{method}{SEPARATOR}{spec}"


def declare_pooled(method: str, spec: PoolSpec) -> str:
    """Declare `<method>:<pool>` (module docstring), once; its name."""
    name = pooled_name(method, spec)
    if name in METHODS:
        return name
    base = METHODS[method]
    declare_method(
        replace(
            base, name=name, label=f"{base.label} on {spec}", pool=spec.pool, matcher=spec.matcher
        ),
        settings=SETTINGS.get(method),
    )
    for registry in (POLICIES, MULTIVIEW):
        if method in registry:
            registry[name] = registry[method]
    if method in plugins.ORIGIN:
        plugins.ORIGIN[name] = plugins.ORIGIN[method]
    return name


def known(name: str) -> str:
    """`name`, declared where it is a pooled name not declared in this process yet (a
    worker's); one line where it names no method."""
    if name not in METHODS and SEPARATOR in name:
        method, _, text = name.partition(SEPARATOR)
        if METHODS.get(method) is not None and METHODS[method].kind in POOLED_KINDS:
            return declare_pooled(method, PoolSpec.parse(text))
    if name not in METHODS:
        raise BenchError(f"unknown method {name!r}; valid: {', '.join(METHODS)}")
    return name


def on_pool(method: str, spec: PoolSpec, own: PoolSpec) -> str | None:
    """The name `method` runs under on the grid's pool `spec` (`own`: the run's pool);
    None where it does not run there (module docstring)."""
    m = METHODS[method]
    if m.kind not in POOLED_KINDS:
        return None
    if SEPARATOR in method:  # a pooled name: on its own pool and matcher alone
        return method if spec == PoolSpec(m.pool, m.matcher) else None
    if m.pool:  # bound to one detector: under its name with its matcher, or on the run's pool
        if m.pool != spec.pool:
            return None
        return method if spec.matcher == m.matcher or spec == own else declare_pooled(method, spec)
    return method if spec == own else declare_pooled(method, spec)


def placement(methods, specs, own: PoolSpec) -> tuple[tuple[str, ...], list[str]]:
    """The names of the grid's methods on its pools (`specs`; empty: the run's own), each
    method's in the pools' order, with each named pool's peer (`pool_peer`), and a line
    for each method that runs on none of them."""
    peers = [pool_peer(s.pool) for s in specs]
    methods = (*methods, *(p for p in peers if p and p not in methods))
    specs = specs or (own,)
    names, said = [], []
    for method in methods:
        m = METHODS[method]
        if m.kind not in POOLED_KINDS:
            names.append(method)  # once, as without pools
            continue
        here = [on_pool(method, s, own) for s in specs]
        names += [n for n in here if n is not None]
        off = [str(s) for s, n in zip(specs, here) if n is None]
        if off and SEPARATOR not in method:  # a pooled name names its one pool itself
            said.append(f"{method} (its pool: {m.pool}) not on {', '.join(off)}")
    if said:
        said = ["methods bound to one pool run on it alone: " + "; ".join(said)]
    return tuple(dict.fromkeys(names)), said


def row_pool(run, method: str) -> dict[str, str]:
    """The `pool` and `matcher` columns of a method's rows under the run's settings (empty
    for a stock-COLMAP peer, which extracts keypoints of its own)."""
    if METHODS[method].kind in (OWN_PIPELINE, TRACKS_PEER):
        return {"pool": "", "matcher": ""}
    cfg = run.for_method(method)
    return {"pool": cfg.detector.detector, "matcher": cfg.backend.matcher}
