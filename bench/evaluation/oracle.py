"""The oracle: a selection that reads ground truth, for an upper reference under the same
budget. It lives on the evaluation side and is never a policy (the front end cannot import
it; `tests/test_layout.py` checks that).

Objective: per view at most B candidates (exactly min(B, N), like every policy), chosen to
maximise the number of matchable ground-truth tracks that have a selected candidate in at
least three views, so they can become points under the headline track protocol.

Matchable tracks (`matchable_tracks`): connected components of the links between two
candidates of different views that correspond in the ground truth *and* are tentative
matches of the whole pools (mutual nearest descriptors passing the ratio test, as the back
end matches by default; on any pool, ALIKED's and DISK's included, and also where
`backend.matcher` is LightGlue, whose cost on whole pools of thousands it does not pay). Ground-truth correspondence alone is not enough: measured on the quick
renders, a third of SIFT candidates have an orientation twin at the same pixel, and of the
same-track pairs an oracle built on geometry alone selected, only 24% (table) and 13%
(facade) became tentative matches, so it lost to texture-only selection.

Greedy (documented, deterministic):
1. Tracks spanning three or more views, least flexible first (fewest views spanned, then
   track id): take the track if three of its views still have room, in the three views
   with the most room left (ties: lower view index).
2. Remaining room, per view in order: candidates of taken tracks in their other views
   (longer tracks), then candidates of the other tracks spanning two or more views (most
   views first), then the rest by detector response.
Within a track, a view's candidate is its one of highest detector response.

The tests solve the objective of step 1 exactly (an integer program, HiGHS via scipy) to
measure the greedy's gap.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bench.backend.matching import tentative_matches
from bench.evaluation.truth import SceneTruth
from bench.frontend.features import Candidates
from bench.frontend.pools import strongest_first
from bench.memo import digest, last_call
from bench.vocabulary import GROUND_TRUTH, ORACLE, Method, declare_method

declare_method(Method(ORACLE, "Oracle (ground truth, reference)", "reference", kind=GROUND_TRUTH))


def _scene_pools(truth: SceneTruth, pools: list[Candidates], ratio: float) -> tuple:
    """What `matchable_tracks` reads: the truth (held by the worker's scene), the pools'
    keypoints and descriptors (the same under either geometry granted) and the ratio."""
    return id(truth), digest(*(a for p in pools for a in (p.xy, p.descriptors))), ratio


@last_call(_scene_pools)
def matchable_tracks(truth: SceneTruth, pools: list[Candidates], ratio: float) -> list[np.ndarray]:
    """Per view, the matchable track of each candidate (see the module docstring); computed
    once per scene on a worker, whatever the budget and geometry (the whole pools matched
    in every pair: 105 s a unit of the dense regime, six times a scene before)."""
    offsets = np.cumsum([0] + [len(p) for p in pools])
    rows, cols = [], []
    for i, j in combinations(range(len(pools)), 2):
        m = tentative_matches(pools[i].descriptors, pools[j].descriptors, ratio)
        ok = truth.correspondences(i, j, m[:, 0], m[:, 1]) if len(m) else np.zeros(0, bool)
        rows.append(offsets[i] + m[ok, 0])
        cols.append(offsets[j] + m[ok, 1])
    n = int(offsets[-1])
    r, c = np.concatenate(rows), np.concatenate(cols)
    _, label = connected_components(
        coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)), directed=False
    )
    return [label[offsets[v] : offsets[v + 1]] for v in range(len(pools))]


def _representatives(track: list[np.ndarray], response: list[np.ndarray]) -> dict:
    """{(track id, view): the view's candidate of that track with the highest response}."""
    rep = {}
    for v, (t, r) in enumerate(zip(track, response)):
        order = strongest_first(r)
        for k in order[::-1]:  # later (weaker) writes are overwritten by stronger ones
            rep[int(t[k]), v] = int(k)
    return rep


def oracle_select(
    track: list[np.ndarray], response: list[np.ndarray], budget: int
) -> list[np.ndarray]:
    """Per view, min(B, N) distinct candidate indices (see the module docstring)."""
    n_views = len(track)
    rep = _representatives(track, response)
    spans: dict[int, list[int]] = {}
    for t, v in sorted(rep):
        spans.setdefault(t, []).append(v)
    room = np.array([min(budget, len(t)) for t in track])
    chosen: list[list[int]] = [[] for _ in range(n_views)]
    taken = set()
    for t in sorted((t for t in spans if len(spans[t]) >= 3), key=lambda t: (len(spans[t]), t)):
        open_views = [v for v in spans[t] if room[v] > 0]
        if len(open_views) >= 3:
            for v in sorted(open_views, key=lambda v: (-room[v], v))[:3]:
                chosen[v].append(rep[t, v])
                room[v] -= 1
            taken.add(t)
    for v in range(n_views):
        picked = set(chosen[v])
        extend = [rep[t, v] for t in sorted(taken) if v in spans[t]]
        pairs = sorted(
            (t for t in spans if t not in taken and len(spans[t]) >= 2 and v in spans[t]),
            key=lambda t: (-len(spans[t]), t),
        )
        rest = strongest_first(response[v])
        for k in [*extend, *(rep[t, v] for t in pairs), *rest.tolist()]:
            if room[v] == 0:
                break
            if k not in picked:
                picked.add(k)
                chosen[v].append(k)
                room[v] -= 1
    return [np.sort(np.array(c, dtype=np.int64)) for c in chosen]
