"""How an equal-count unit (`bench.backend.equal_count`) computes and stores its
prediction: the peer's count per view from the unit's images, then its policy's selection
at those counts, matched, verified and reconstructed like any selection
(`bench.harness.predict.store_selection`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bench.backend.equal_count import EQUAL, equal_selection, peer_counts
from bench.backend.matching import matcher
from bench.backend.peers import COLMAP_SIFT
from bench.frontend.policies import PolicyInput
from bench.frontend.views import Source
from bench.harness.evaluate import selection_shared
from bench.harness.predict import store_selection
from bench.results import PREDICTION
from bench.vocabulary import METHODS, implemented_by


def store_equal(scene, unit, jobs, cfg, ws, record) -> None:
    """The `Store` of an equal-count method (`bench.harness.predict.Store`)."""
    fe = next(iter(scene.fronts.values()))
    names, cams = [v.name for v in fe.views], [v.camera for v in fe.views]
    peer = EQUAL[unit.method][1]
    images, sift = Source.of(scene.entry).images, ws.renders / COLMAP_SIFT
    counts = peer_counts(images, names, cams, peer, unit.budget, sift)

    def select(fe, truth, unit, cfg):
        inputs = [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
        policy_cfg = cfg.policy_config(unit.method)
        backend = cfg.backend
        if METHODS[unit.method].matcher:
            backend = replace(backend, matcher=METHODS[unit.method].matcher)
        match = matcher(cams, fe.pools, backend, cfg.detector.detector)
        sel = equal_selection(unit.method, inputs, counts, unit.seed, policy_cfg, match)
        return sel, []

    record["counts"] = counts
    store_selection(select)(scene, unit, jobs, cfg, ws, record)


def equal_shared(scene, unit, record, grant, folder):
    """`selection_shared` (`bench.harness.evaluate.Shared`) with the mean number of keypoints
    per view that the unit selected: its counts differ from B, unlike a policy's."""
    shared, seconds, poses = selection_shared(scene, unit, record, grant, folder)
    with np.load(folder / f"{PREDICTION}-{grant}.npz") as arrays:
        sizes = [len(arrays[f"selection_{v}"]) for v in range(len(record["names"]))]
    return shared | {"keypoints_per_view": float(np.mean(sizes))}, seconds, poses


implemented_by(list(EQUAL), store_equal, equal_shared)  # its rows' code hashes start here too
