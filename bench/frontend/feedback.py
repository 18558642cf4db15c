"""`adaptive-loop`: the paper's Figure 1 loop, selection revised from its own matches.

Round 0 is the `adaptive-fast` selection (the paper's score with the cheap repeatability
estimate). After each round the caller's `match` (matching and
COLMAP verification of the selection, as the back end does it) reports every pair's
tentative and verified matches; from them and the calibration, per selected keypoint:
its verified track (connected components of the verified matches) and that track's
largest angle between viewing rays (with the poses, or, for views without them, the
relative rotation that the verification of each pair estimated). A keypoint is *useful* when its track spans at least
three views at an angle of at least 1.5 degrees (what the headline protocol triangulates).
Then, per view and tile:

* useful keypoints are kept;
* the score threshold of the tile rises to the median adaptive score of its keypoints
  that had a tentative match but failed verification; candidates below it, and every
  keypoint already tried without becoming useful, are passed over;
* the rest of the budget is shared among tiles in proportion to yield + 0.05, where yield
  is the tile's useful / selected keypoints (untried tiles: the view's mean yield), capped
  by the candidates a tile has left (largest remainders); what a tile cannot use goes to
  the best remaining candidates anywhere, so the budget is always met.

It sees what a front end sees (images, candidates, signals, calibration) and its own
matching results, never ground truth. The diagnostics of every round are returned for
the run's model folder (`loop.json`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bench import BenchError
from bench.frontend.features import tile_of
from bench.frontend.policies import (
    ADAPTIVE_SIGNALS,
    PolicyConfig,
    PolicyInput,
    adaptive_score,
    capped_greedy,
    contract_violation,
    multiview_policy,
    settings_for,
)
from bench.frontend.pools import strongest_first


@dataclass(frozen=True)
class LoopConfig(PolicyConfig):
    """`adaptive-loop`'s settings."""

    loop_rounds: int = 2
    """How many times the selection is revised from its own matches."""

    def validate(self) -> LoopConfig:
        super().validate()
        if self.loop_rounds < 0:
            raise BenchError(f"loop_rounds must be >= 0, got {self.loop_rounds}")
        return self


NAME = "adaptive-loop"
MIN_ANGLE_DEG = 1.5
EXPLORE = 0.05

Match = Callable[[list[np.ndarray]], list]
"""Selections per view -> pairs with `i`, `j`, `tentative` and `verified` (M, 2) index
arrays into the selections (`bench.backend.matching.PairMatches`)."""


def keypoint_diagnostics(inputs: list[PolicyInput], sel: list[np.ndarray], pairs) -> list[dict]:
    """Per view, per selected keypoint: tentative (bool), verified (bool), track views and
    track angle (degrees)."""
    offsets = np.cumsum([0] + [len(s) for s in sel])
    n = offsets[-1]
    tent, ver = np.zeros(n, bool), np.zeros(n, bool)
    rows, cols, angles = [], [], []
    for p in pairs:
        a, b = offsets[p.i], offsets[p.j]
        tent[a + p.tentative[:, 0]] = tent[b + p.tentative[:, 1]] = True
        if not len(p.verified):
            continue
        ia, jb = p.verified[:, 0], p.verified[:, 1]
        ver[a + ia] = ver[b + jb] = True
        ra = inputs[p.i].view.camera.rays(inputs[p.i].candidates.xy[sel[p.i][ia]])
        rb = inputs[p.j].view.camera.rays(inputs[p.j].candidates.xy[sel[p.j][jb]])
        rows.append(a + ia)
        cols.append(b + jb)
        if not inputs[p.i].view.posed:  # camera-frame rays: a into b's frame
            if p.rotation is None:  # verified without a relative pose: angle unknown, 0
                angles.append(np.zeros(len(ia)))
                continue
            ra = ra @ p.rotation.T
        angles.append(np.degrees(np.arccos(np.clip((ra * rb).sum(1), -1, 1))))
    r, c = (np.concatenate(x) if x else np.zeros(0, int) for x in (rows, cols))
    ang = np.concatenate(angles) if angles else np.zeros(0)
    _, label = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n)))
    view_of = np.repeat(np.arange(len(sel)), np.diff(offsets))
    views = np.zeros(label.max() + 1 if n else 0, int)
    for v in range(len(sel)):
        views[np.unique(label[view_of == v])] += 1
    track_angle = np.zeros(len(views))
    np.maximum.at(track_angle, label[r], ang)
    return [
        {
            "tentative": tent[offsets[v] : offsets[v + 1]],
            "verified": ver[offsets[v] : offsets[v + 1]],
            "track_views": views[label[offsets[v] : offsets[v + 1]]],
            "track_angle": track_angle[label[offsets[v] : offsets[v + 1]]],
        }
        for v in range(len(sel))
    ]


def _apportion(total: int, weight: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """Integers summing to at most `total`, proportional to weight, none above cap
    (largest remainders; what a capped tile cannot take goes to the others)."""
    quota = np.zeros(len(weight), int)
    open_ = (cap > 0) & (weight > 0)
    while quota.sum() < total and open_.any():
        left = total - quota.sum()
        share = left * np.where(open_, weight, 0) / weight[open_].sum()
        add = np.minimum(np.floor(share).astype(int), cap - quota)
        rest = left - add.sum()
        order = np.lexsort((np.arange(len(share)), -(share - np.floor(share))))
        for k in order[open_[order]]:
            if rest <= 0:
                break
            if quota[k] + add[k] < cap[k]:
                add[k] += 1
                rest -= 1
        if add.sum() == 0:
            break
        quota += add
        open_ &= quota < cap
    return quota


def revise(
    inp: PolicyInput,
    budget: int,
    cfg: PolicyConfig,
    sel: np.ndarray,
    diag: dict,
    tried: np.ndarray,
    threshold: np.ndarray,
) -> tuple[np.ndarray, dict]:
    """One view's next selection from its last one and its diagnostics (module docstring)."""
    cam = inp.view.camera
    score = adaptive_score(inp.signals, cfg.weights)
    tile = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
    n_tiles = cfg.tiles[0] * cfg.tiles[1]
    useful = (diag["track_views"] >= 3) & (diag["track_angle"] >= MIN_ANGLE_DEG)
    failed = diag["tentative"] & ~diag["verified"]
    tried[sel] = True
    selected = np.bincount(tile[sel], minlength=n_tiles)
    good = np.bincount(tile[sel[useful]], minlength=n_tiles)
    for t in np.unique(tile[sel[failed]]):
        bad = sel[failed & (tile[sel] == t)]
        threshold[t] = max(threshold[t], float(np.median(score[bad])))
    yield_ = np.divide(good, selected, out=np.zeros(n_tiles), where=selected > 0)
    mean_yield = good.sum() / max(selected.sum(), 1)
    weight = np.where(selected > 0, yield_, mean_yield) + EXPLORE
    keep = sel[useful]
    want = min(budget, len(score))
    open_ = ~tried & (score >= threshold[tile])
    quota = _apportion(want - len(keep), weight, np.bincount(tile[open_], minlength=n_tiles))
    picks = [keep]
    for t in np.flatnonzero(quota):
        members = np.flatnonzero(open_ & (tile == t))
        picks.append(members[strongest_first(score[members])][: quota[t]])
    chosen = np.concatenate(picks).astype(np.int64)
    if len(chosen) < want:  # not enough untried candidates above threshold: best of the rest
        order = strongest_first(score)
        rest = order[~np.isin(order, chosen)]
        chosen = np.concatenate([chosen, rest[: want - len(chosen)]])
    log = {
        "kept": int(len(keep)),
        "yield": np.round(yield_, 4).tolist(),
        "quota": quota.tolist(),
        "threshold": np.round(np.where(np.isfinite(threshold), threshold, -1), 4).tolist(),
    }
    return chosen, log


@multiview_policy(NAME, "Adaptive feedback loop", reads=ADAPTIVE_SIGNALS, config=LoopConfig)
def feedback_select(
    inputs: list[PolicyInput], budget: int, cfg: PolicyConfig, match: Match
) -> tuple[list[np.ndarray], list[dict]]:
    """The loop's final selection per view, and every round's diagnostics (its own
    settings from `cfg` if it is a `LoopConfig`, else their defaults)."""
    cfg = settings_for(NAME, cfg)
    sel = [
        np.sort(capped_greedy(adaptive_score(i.signals, cfg.weights), i, budget, cfg))
        for i in inputs
    ]
    n_tiles = cfg.tiles[0] * cfg.tiles[1]
    tried = [np.zeros(len(i.candidates), bool) for i in inputs]
    threshold = [np.full(n_tiles, -np.inf) for _ in inputs]
    rounds = []
    for r in range(cfg.loop_rounds):
        sizes = [len(x) for x in sel]
        pairs = match(sel)
        diags = keypoint_diagnostics(inputs, sel, pairs)
        logs = []
        for v, inp in enumerate(inputs):
            chosen, log = revise(inp, budget, cfg, sel[v], diags[v], tried[v], threshold[v])
            sel[v] = np.sort(chosen)  # a set: the order never reaches the matcher
            logs.append(log)
        rounds.append(
            {
                "round": r,
                "selected": sizes,
                "pair_tentative": [len(p.tentative) for p in pairs],
                "pair_verified": [len(p.verified) for p in pairs],
                "views": logs,
            }
        )
    for v, inp in enumerate(inputs):
        n = len(inp.candidates)
        broken = contract_violation(sel[v], min(budget, n), n)
        if broken:
            raise RuntimeError(f"{NAME} broke the contract rule '{broken}'")
    return sel, rounds
