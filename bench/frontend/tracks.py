"""`track-first`: keep, in every view, the keypoints whose verified matches reach the most
views (issue 49, the small-budget gap).

Why, for photographs in general: an incremental mapper (COLMAP's) starts from a pair of
views with enough verified inliers and registers every further view from 2D-3D
correspondences with points already triangulated (at least 30 inliers), so at a small
budget a view's keypoints count for mapping only where the same physical point is also
kept in two or more other views. A per-view score (texture, response, the adaptive score)
ranks each view's candidates on its own, so two views keep partly different points; the
number of views a candidate's verified track spans is one number shared by every member of
the track, so ranking by it keeps the same points in every view. The tracks come from the
images alone: the back end's own matching and verification (`match`, as `adaptive-loop`
uses it), on a first pass of each view's candidates.

The selection: (1) the first pass, `first_pass` x B candidates per view by the
`cross-view` score under the soft tile cap (`capped_greedy`); (2) their matches, verified
by the back end, all pairs of views; (3) tracks: connected components of the verified
matches, and for each candidate the number of distinct views of its track (0 if it has no
verified match); (4) the final B: by that number first, the `cross-view` score within it,
under the same soft tile cap. Measured on the small-budget slice in
`benchmarks/small_budget.py` (retired: `git show 3adebc1:benchmarks/small_budget.py`;
docs/protocol.md, "The small-budget gap").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bench import BenchError
from bench.frontend.policies import (
    ADAPTIVE_SIGNALS,
    CrossViewConfig,
    PolicyInput,
    adaptive_score,
    capped_greedy,
    multiview_policy,
    settings_for,
)
from bench.frontend.selection import BY_VIEW

NAME = "track-first"


@dataclass(frozen=True)
class TrackFirstConfig(CrossViewConfig):
    """`track-first`'s settings (the `cross-view` score's, and the first pass)."""

    first_pass: int = 4
    """The first pass holds this many times B candidates per view (all, where fewer)."""

    def validate(self) -> TrackFirstConfig:
        super().validate()
        if self.first_pass < 1:
            raise BenchError(f"first_pass must be >= 1, got {self.first_pass}")
        return self


def cross_view_score(inp: PolicyInput, cfg: CrossViewConfig) -> np.ndarray:
    """`cross-view`'s score: the adaptive score plus epipolar_weight x the epipolar signal."""
    return adaptive_score(inp.signals, cfg.weights) + cfg.epipolar_weight * inp.signals.epipolar


def track_views(sizes: list[int], pairs) -> list[np.ndarray]:
    """Per view, for each of its `sizes[v]` keypoints, the number of distinct views of its
    track (connected component of the verified matches of `pairs`), 0 where it has none."""
    offset = np.cumsum([0, *sizes])
    n = int(offset[-1])
    rows = [offset[p.i] + p.verified[:, 0] for p in pairs if len(p.verified)]
    cols = [offset[p.j] + p.verified[:, 1] for p in pairs if len(p.verified)]
    r = np.concatenate(rows).astype(np.int64) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols).astype(np.int64) if cols else np.zeros(0, np.int64)
    _, label = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)))
    view = np.repeat(np.arange(len(sizes)), sizes)
    members = np.unique(np.c_[label, view], axis=0)  # (component, view) once each
    views = np.bincount(members[:, 0], minlength=n)[label]
    views[views < 2] = 0
    return [views[offset[v] : offset[v + 1]] for v in range(len(sizes))]


def track_first_select(
    inputs: list[PolicyInput], budgets: list[int], cfg: TrackFirstConfig, match
) -> list[np.ndarray]:
    """Each view's selection of `budgets[v]` (module docstring), ascending."""
    scores = [cross_view_score(i, cfg) for i in inputs]
    first = [
        np.sort(capped_greedy(s, i, cfg.first_pass * b, cfg)) if b > 0 else np.zeros(0, int)
        for i, s, b in zip(inputs, scores, budgets)
    ]
    spans = track_views([len(f) for f in first], match(first))
    out = []
    for inp, s, b, f, span in zip(inputs, scores, budgets, first, spans):
        if b <= 0:
            out.append(np.zeros(0, np.int64))
            continue
        views = np.zeros(len(inp.candidates))
        views[f] = span
        within = (s - s.min()) / (np.ptp(s) + 1e-12) if len(s) else s  # [0, 1]: below 1 view
        out.append(np.sort(capped_greedy(views * 2 + within, inp, b, cfg)))
    return out


BY_VIEW[NAME] = track_first_select


@multiview_policy(
    NAME,
    "Verified track length first (cross-view score within)",
    reads=(*ADAPTIVE_SIGNALS, "epipolar"),
    config=TrackFirstConfig,
)
def track_first(inputs: list[PolicyInput], budget: int, cfg, match):
    """B per view by verified track length, then the cross-view score (module docstring)."""
    cfg = settings_for(NAME, cfg)
    return track_first_select(inputs, [budget] * len(inputs), cfg, match), []
