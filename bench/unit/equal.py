"""How an equal-count unit (`bench.backend.equal_count`) computes and stores its
prediction: the peer's count per view from the unit's images, then its policy's selection
at those counts through the one select-and-match path (`bench.unit.select_match`, with
the method's own settings), matched, verified and reconstructed like any selection
(`bench.unit.predict.store_selection`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bench.backend.equal_count import EQUAL, peer_counts
from bench.backend.peers import COLMAP_SIFT
from bench.frontend.views import Source
from bench.results import PREDICTION
from bench.unit import select_match
from bench.unit.evaluate import selection_shared
from bench.unit.predict import store_selection


def store_equal(scene, unit, jobs, cfg, ws, record) -> None:
    """The `Store` of an equal-count method (`bench.unit.predict.Store`)."""
    fe = next(iter(scene.fronts.values()))
    names, cams = [v.name for v in fe.views], [v.camera for v in fe.views]
    peer = EQUAL[unit.method][1]
    images, sift = Source.of(scene.entry).images, ws.renders / COLMAP_SIFT
    counts = peer_counts(images, names, cams, peer, unit.budget, sift)

    def select(fe, truth, unit, cfg):
        policy = EQUAL[unit.method][0]  # given the method's own settings
        own = replace(cfg, methods=cfg.methods | {policy: cfg.own(unit.method)})
        selections, rounds, _ = select_match.select(
            fe.views, fe.pools, fe.signals, replace(unit, method=policy), own, counts
        )
        return selections, rounds

    record["counts"] = counts
    store_selection(select)(scene, unit, jobs, cfg, ws, record)


def equal_shared(scene, unit, record, grant, folder):
    """`selection_shared` (`bench.unit.evaluate.Shared`) with the mean number of keypoints
    per view that the unit selected: its counts differ from B, unlike a policy's."""
    shared, seconds, poses = selection_shared(scene, unit, record, grant, folder)
    with np.load(folder / f"{PREDICTION}-{grant}.npz") as arrays:
        sizes = [len(arrays[f"selection_{v}"]) for v in range(len(record["names"]))]
    return shared | {"keypoints_per_view": float(np.mean(sizes))}, seconds, poses
