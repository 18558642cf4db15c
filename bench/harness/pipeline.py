"""One unit of work, end to end: (render entry, policy, budget) -> one row per task and
track protocol.

render entry -> front end (cached) under the geometry the task grants (`GRANTS`) ->
selection of B per view (a policy, or the oracle on the evaluation side) -> match ->
verify -> for each task: reconstruct (COLMAP) -> export the model -> evaluate against
ground truth. The tasks and protocols of one grant share the selection, matching and
verification, so they see exactly the same matches; a selection that does not depend on
the grant (it reads no geometry) is matched once for both.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import time
import zlib
from dataclasses import asdict, dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from bench.backend import matching, peers, reconstruction
from bench.backend.matching import BackendConfig, match_and_verify
from bench.backend.peers import PEERS, run_peer
from bench.backend.reconstruction import (
    PROTOCOLS,
    known_pose_model,
    known_pose_task,
    mapping_task,
)
from bench.camera import Camera
from bench.evaluation import groundtruth, metrics, oracle, poses
from bench.evaluation.metrics import SceneTruth, coverage_pct, evaluate_known_pose, match_metrics
from bench.evaluation.oracle import matchable_tracks, oracle_select
from bench.evaluation.poses import evaluate_mapping
from bench.files import content_key, source_hash, temp_dir_beside, write_text_atomic
from bench.frontend import features, feedback, geometry, policies, signals, stage, views
from bench.frontend.features import Candidates, DetectorConfig
from bench.frontend.geometry import IMAGES, RIG
from bench.frontend.policies import (
    SIGNALS_USED,
    PolicyConfig,
    PolicyInput,
    select,
    weights_file,
)
from bench.frontend.signals import SignalConfig, Signals, seconds_of
from bench.frontend.stage import FrontEnd
from bench.frontend.views import Source, View, source_key
from bench.harness import plugins
from bench.render.config import RenderConfig

TASKS = ("tri", "sfm")
"""Reconstruction tasks: `tri` triangulates with the known poses; `sfm` maps with unknown
poses and is scored by pose accuracy."""
GRANTS = {"tri": RIG, "sfm": IMAGES}
"""What a task's selection may see of the views' geometry, the one switch: `tri` the rig's
poses (its premise); `sfm` the images and intrinsics only, like its mapper and the COLMAP
peers it is compared with (`bench.frontend.geometry`)."""
ORACLE = "oracle"
"""The ground-truth selection of `bench.evaluation.oracle`: a reference, never a policy."""
REFERENCES = ("all", ORACLE, *PEERS)
"""Rows that are references or peers, not contenders (never a "best baseline")."""


@cache
def code_hash() -> str:
    """Hash of the source of every stage that produces a row's numbers after the render
    (whose code is in the render key): front end, back end, evaluation and this module."""
    return source_hash(
        views,
        features,
        geometry,
        signals,
        policies,
        feedback,
        plugins,
        stage,
        matching,
        reconstruction,
        peers,
        groundtruth,
        metrics,
        oracle,
        poses,
        sys.modules[__name__],
    )


@dataclass(frozen=True)
class RunConfig:
    """The settings that decide a run's metrics; its hash, with the code's, is stored in
    every row (`config_hash`, per row: `row_hash`)."""

    render: RenderConfig | None = field(default_factory=RenderConfig)
    """None for a dataset, whose images are not rendered."""
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    signals: SignalConfig = field(default_factory=SignalConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)

    def as_dict(self) -> dict:
        """The settings that decide every row: all of them but the policy modules, whose
        content decides their own policies' rows only (`row_hash`)."""
        settings = asdict(self)
        del settings["policy"]["modules"]
        return settings

    @property
    def hash(self) -> str:
        """Of the settings, the code and the learned weights."""
        return content_key(
            {
                "settings": self.as_dict(),
                "code": code_hash(),
                "inputs": plugins.files_hash([weights_file(self.policy.learned_weights)]),
            }
        )


def row_hash(cfg: RunConfig, policy: str) -> str:
    """The `config_hash` of a policy's rows: the settings' and code's, and for a policy
    from a module (`--policy-module`, an entry point) its module's content as well."""
    plugins.load(cfg.policy.modules)
    origin = plugins.ORIGIN.get(policy)
    return content_key([cfg.hash, plugins.files_hash([origin])]) if origin else cfg.hash


def policy_rng(seed: int, policy: str, budget: int, view: int) -> np.random.Generator:
    """The generator of one unit of work, derived from the run's seed."""
    return np.random.default_rng([seed, zlib.crc32(policy.encode()), budget, view])


def select_features(
    fe: FrontEnd, truth: SceneTruth, policy: str, budget: int, seed: int, cfg: RunConfig
) -> tuple[list[np.ndarray], float, list[dict]]:
    """Every view's selection, the seconds it took, and the feedback loop's rounds (none
    for other policies)."""
    t = time.perf_counter()
    if policy == ORACLE:
        tracks = matchable_tracks(truth, fe.pools, cfg.backend.ratio)
        sel, rounds = oracle_select(tracks, [c.response for c in fe.pools], budget), []
    else:
        sel, rounds = policy_selection(policy, fe.views, fe.pools, fe.signals, budget, seed, cfg)
    return sel, time.perf_counter() - t, rounds


def matcher(cams: list[Camera], pools: list[Candidates], backend: BackendConfig):
    """Selections per view -> the back end's verified pairs of those keypoints."""

    def match(selection: list[np.ndarray]) -> list:
        xy = [c.xy[s] for c, s in zip(pools, selection)]
        desc = [c.descriptors[s] for c, s in zip(pools, selection)]
        return match_and_verify(cams, xy, desc, backend)[0]

    return match


def policy_selection(
    policy: str,
    views: list[View],
    pools: list[Candidates],
    sigs: list[Signals],
    budget: int,
    seed: int,
    cfg: RunConfig,
) -> tuple[list[np.ndarray], list[dict]]:
    """A policy's selection in every view (outside policies registered first), and the
    feedback loop's rounds (none for other policies)."""
    inputs = [PolicyInput(v, c, s) for v, c, s in zip(views, pools, sigs)]
    if policy == feedback.NAME:
        match = matcher([v.camera for v in views], pools, cfg.backend)
        return feedback.feedback_select(inputs, budget, cfg.policy, match)
    plugins.load(cfg.policy.modules)
    rngs = [policy_rng(seed, policy, budget, v.index) for v in views]
    return [select(policy, i, budget, r, cfg.policy) for i, r in zip(inputs, rngs)], []


def signals_used(policy: str) -> tuple[str, ...]:
    """The signals a policy reads (for its front-end cost)."""
    return feedback.SIGNALS_USED if policy == feedback.NAME else SIGNALS_USED.get(policy, ())


def export_model(model, out: Path) -> None:
    """COLMAP text model + points.ply, written to a temporary directory then renamed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_dir_beside(out)
    try:
        model.write_text(str(tmp))
        model.export_PLY(str(tmp / "points.ply"))
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def model_dir(
    results: Path, scene: str, seed: int, policy: str, budget: int, task: str, protocol: str
) -> Path:
    """Where a run's model is exported: the headline (`tri`, `multiview`) at the top of the
    run's folder, every other task or protocol in a subfolder named after it."""
    run = Path(results) / "models" / f"{scene}-s{seed}" / f"{policy}-b{budget}"
    return (
        run
        if (task, protocol) == ("tri", "multiview")
        else run / (protocol if task == "tri" else task)
    )


def run_unit(
    entry: Path,
    fronts: dict[str, FrontEnd],
    truth: SceneTruth,
    scene: str,
    seed: int,
    policy: str,
    budget: int,
    jobs: list[tuple[str, str]],
    cfg: RunConfig,
    results: Path,
) -> list[dict]:
    """One row per (task, protocol) in `jobs`: identification, every metric, stage timings
    (ms) and a failure reason if any. Each task selects from the front end of the geometry
    it grants (`fronts`, by grant)."""
    rows, matched = [], {}
    for grant in dict.fromkeys(GRANTS[task] for task, _ in jobs):
        fe = fronts[grant]
        selections, select_s, rounds = select_features(fe, truth, policy, budget, seed, cfg)
        key = repr(([s.tolist() for s in selections], rounds))
        if key not in matched:
            matched[key] = _matched(fe, truth, policy, selections, rounds, cfg)
        xy, pairs, shared, match_s = matched[key]
        used = signals_used(policy)
        seconds = {
            "detect": fe.seconds["detect"],
            "signals": seconds_of(fe.seconds, used),
            "select": select_s,
            **match_s,
        }
        cams = [v.camera for v in fe.views]
        names = [v.name for v in fe.views]
        image_dir = Source.of(entry).images
        for task, protocol in [j for j in jobs if GRANTS[j[0]] == grant]:
            out = model_dir(results, scene, seed, policy, budget, task, protocol)
            if task == "tri":
                rec = known_pose_task(image_dir, cams, names, xy, pairs, cfg.backend, protocol)
                model = rec.model if rec.model is not None else known_pose_model(cams, names, xy)
                export_model(model, out)
            else:
                rec = mapping_task(image_dir, cams, names, xy, pairs, cfg.backend, protocol)
                _export_or_clear(rec.model, out)
            t = time.perf_counter()
            if task == "tri":
                scores = evaluate_known_pose(truth, rec.model, PROTOCOLS[protocol])
            else:
                scores = evaluate_mapping(truth, rec.model, _view_of_name(names))
            timing = seconds | {
                "task": rec.seconds,
                "evaluate": time.perf_counter() - t,
            }
            ident = (entry, scene, seed, policy, budget, task, protocol, cfg)
            rows.append(_row(ident, shared | scores, timing, rec.failure))
        if rounds:
            first = next(j for j in jobs if GRANTS[j[0]] == grant)
            folder = model_dir(results, scene, seed, policy, budget, *first)
            folder.mkdir(parents=True, exist_ok=True)
            write_text_atomic(folder / "loop.json", json.dumps(rounds, indent=1))
    return rows


def _matched(
    fe: FrontEnd,
    truth: SceneTruth,
    policy: str,
    selections: list[np.ndarray],
    rounds: list[dict],
    cfg: RunConfig,
) -> tuple[list[np.ndarray], list, dict, dict[str, float]]:
    """A selection's keypoints, verified pairs, the metrics of its matches, and the seconds
    of matching, verification and the match metrics."""
    xy = [c.xy[s] for c, s in zip(fe.pools, selections)]
    desc = [c.descriptors[s] for c, s in zip(fe.pools, selections)]
    pairs, seconds = match_and_verify([v.camera for v in fe.views], xy, desc, cfg.backend)
    t = time.perf_counter()
    earlier = [(r["selected"], r["pair_tentative"], r["pair_verified"]) for r in rounds]
    shared = match_metrics(truth, fe.pools, selections, pairs, len(signals_used(policy)), earlier)
    shared["ground_truth"] = truth.kind
    seconds["evaluate_matches"] = time.perf_counter() - t
    return xy, pairs, shared, seconds


def run_peer_unit(
    entry: Path,
    fronts: dict[str, FrontEnd],
    truth: SceneTruth,
    scene: str,
    seed: int,
    peer: str,
    budget: int,
    jobs: list[tuple[str, str]],
    cfg: RunConfig,
    results: Path,
) -> list[dict]:
    """The rows (task `sfm`, one per protocol) of a stock-COLMAP peer (`bench.backend.peers`)."""
    fe = fronts[GRANTS["sfm"]]
    names = [v.name for v in fe.views]
    cams = [v.camera for v in fe.views]
    image_dir = Source.of(entry).images
    run = run_peer(image_dir, names, cams, peer, budget, cfg.backend, [pr for _, pr in jobs])
    shared = {
        "tentative_matches": run.tentative,
        "verified_matches": run.verified,
        "inlier_pct": 100.0 * run.verified / run.tentative if run.tentative else math.nan,
        "coverage_pct": coverage_pct(run.keypoints, cams),
        "keypoints_per_view": float(np.mean([len(k) for k in run.keypoints])),
        "ground_truth": truth.kind,
    }
    rows = []
    for task, protocol in jobs:
        rec = run.recs[protocol]
        _export_or_clear(rec.model, model_dir(results, scene, seed, peer, budget, task, protocol))
        t = time.perf_counter()
        scores = evaluate_mapping(truth, rec.model, _view_of_name(names))
        timing = run.seconds | {"task": rec.seconds, "evaluate": time.perf_counter() - t}
        ident = (entry, scene, seed, peer, budget, task, protocol, cfg)
        rows.append(_row(ident, shared | scores, timing, rec.failure))
    return rows


def _view_of_name(names: list[str]) -> dict[str, int]:
    return {name: k for k, name in enumerate(names)}


def _export_or_clear(model, out: Path) -> None:
    """Export a model; without one, remove what an earlier run left there."""
    if model is not None:
        export_model(model, out)
    elif out.exists():
        shutil.rmtree(out)


def row_identity(ident: tuple) -> dict:
    """The columns that say which run a row is: (entry, scene, seed, policy, budget, task,
    protocol, config) as a dict."""
    entry, scene, seed, policy, budget, task, protocol, cfg = ident
    return {
        "scene": scene,
        "seed": seed,
        "policy": policy,
        "budget": budget,
        "task": task,
        "protocol": protocol,
        "render_key": source_key(entry),
        "config_hash": row_hash(cfg, policy),
    }


def _row(ident: tuple, metrics: dict, timing: dict[str, float], failure: str | None) -> dict:
    meta = Path(ident[0]) / "meta.json"  # a render entry's; a dataset has none
    render_s = (
        float(np.mean(json.loads(meta.read_text())["seconds_per_view"]))
        if meta.is_file()
        else math.nan
    )
    row = {
        **row_identity(ident),
        **metrics,
        "render_s_per_view": render_s,
        **{f"{k}_ms": 1000 * v for k, v in timing.items()},
        "wall_ms": 1000 * sum(v for k, v in timing.items() if not k.startswith("evaluate")),
        "status": "ok" if failure is None else "failed",
        "failure": failure or "",
    }
    if failure:
        row["rmse"] = row["median_error"] = math.nan
    return row
