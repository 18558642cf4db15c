"""A unit's stored prediction scored against ground truth: one row per job (task, track
protocol) with the identification, every metric, the seconds of each stage (ms) and a
failure reason if any.

It reads the prediction `bench.unit.predict` stored (selections, verified matches,
exported models, seconds) and never selects, matches or maps, so `bench run --reevaluate`
(or a change to a metric alone) re-scores a grid in seconds per unit. What a task keeps
beside a model (`TaskRunner.keep`: tri's point errors, for Figure 2) is written here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bench.evaluation.metrics import coverage_pct, match_metrics
from bench.frontend.colmap_model import read_reconstruction
from bench.frontend.signals import seconds_of
from bench.frontend.views import Source, pixels_key, source_key
from bench.render.entry import entry_meta
from bench.results import PREDICTION, Workspace
from bench.unit.config import RunConfig
from bench.unit.predict import (
    Keys,
    LoadedScene,
    read_record,
    stored_pairs,
    stored_poses,
)
from bench.unit.tasks import TASK_RUNNERS
from bench.vocabulary import BAG, METHODS, METRICS, Job, Unit

Shared = Callable[[LoadedScene, Unit, dict, str, Path], tuple[dict, dict, dict]]
"""How a kind of method's stored prediction is read back (`bench.unit.methods`): (the
scene, the unit, its record, a grant, its folder) -> (the metrics the grant's jobs share,
the seconds of the stages before the task, the stored relative poses of its pairs)."""


def evaluate(
    scene: LoadedScene,
    unit: Unit,
    jobs: list[Job],
    cfg: RunConfig,
    ws: Workspace,
    read: Shared,
    keys: Keys,
) -> list[dict]:
    """The rows of `jobs` from the unit's stored prediction, read back by its kind's
    `read` (module docstring)."""
    folder = ws.unit_dir(unit)
    record = read_record(folder)
    names = record["names"]
    shared = {}
    for grant in {record["jobs"][j.key]["grant"] for j in jobs}:
        shared[grant] = read(scene, unit, record, grant, folder)
    rows, render_s = [], render_seconds(scene.entry)
    for job, ident in zip(jobs, identities(scene.entry, unit, jobs, keys)):
        done = record["jobs"][job.key]
        metrics_of, seconds, poses = shared[done["grant"]]
        out = ws.model_dir(unit, job)
        model = read_reconstruction(out) if done["model"] else None
        t = time.perf_counter()
        runner = TASK_RUNNERS[job.task]
        scores = runner.evaluate(scene.truth, model, names, job.protocol, poses)
        if runner.keep is not None:
            runner.keep(model, scene.truth, out)
        timing = seconds | {"task": done["task_s"], "evaluate": time.perf_counter() - t}
        rows.append(make_row(ident, metrics_of | scores, timing, done["failure"], render_s))
    return rows


def own_pipeline_shared(scene: LoadedScene, unit: Unit, record: dict, grant: str, folder: Path):
    """`Shared` of a method with a pipeline of its own (stock COLMAP): its keypoints and
    matches as its database held them."""
    with np.load(folder / f"{PREDICTION}-{grant}.npz") as arrays:
        keypoints = [arrays[f"keypoints_{v}"] for v in range(len(record["names"]))]
        peer = record["peer"]
        poses = stored_poses(peer.get("pairs", []), arrays)
    shared = {
        "tentative_matches": peer["tentative"],
        "verified_matches": peer["verified"],
        "inlier_pct": 100.0 * peer["verified"] / peer["tentative"]
        if peer["tentative"]
        else math.nan,
        "coverage_pct": coverage_pct(keypoints, scene.truth.cams),
        "keypoints_per_view": float(np.mean([len(k) for k in keypoints])),
        "ground_truth": scene.truth.kind,
    }
    return shared, dict(peer["seconds"]), poses


def selection_shared(scene: LoadedScene, unit: Unit, record: dict, grant: str, folder: Path):
    """`Shared` of a method that selects from the pools: the metrics of the selection and
    its matches (`bench.evaluation.metrics.match_metrics`)."""
    t = time.perf_counter()
    with np.load(folder / f"{PREDICTION}-{grant}.npz") as arrays:
        stored = record["grants"][grant]
        selections = [arrays[f"selection_{v}"] for v in range(len(record["names"]))]
        pairs = stored_pairs(record, grant, arrays)
        poses = stored_poses(stored["pairs"], arrays)
    fe = scene.fronts[grant]
    reads = METHODS[unit.method].reads
    earlier = [(r["selected"], r["pair_tentative"], r["pair_verified"]) for r in stored["rounds"]]
    shared = match_metrics(scene.truth, fe.pools, selections, pairs, len(reads), earlier)
    shared["ground_truth"] = scene.truth.kind
    seconds = {
        "detect": fe.seconds["detect"],
        "signals": seconds_of(fe.seconds, reads),
        **stored["seconds"],
        "evaluate_matches": time.perf_counter() - t,
    }
    return shared, seconds, poses


def identities(entry: Path, unit: Unit, jobs: list[Job], keys: Keys) -> list[dict]:
    """For each job, the columns that say which run its row is (its key, `KEY`: a dataset's
    bag among them, `Unit.bag`, empty for a rendered scene) and which code and settings
    computed it (what they share, computed once for the unit)."""
    shared = {
        "render_key": source_key(entry),
        "pixels": pixels_key(entry),
        "views": len(unit.bag.split()) or len(Source.of(entry).cameras()),
    }
    return [
        {
            "scene": unit.scene,
            "seed": unit.seed,
            "method": unit.method,
            "budget": unit.budget,
            BAG: unit.bag,
            "task": job.task,
            "protocol": job.protocol,
            **keys.columns,
            **shared,
            "prediction_hash": keys.prediction(job.task),
            "evaluation_hash": keys.evaluation,
        }
        for job in jobs
    ]


def render_seconds(entry: Path) -> float:
    """A render entry's mean seconds per view (NaN for a dataset)."""
    if Source.kind(entry) != "render":
        return math.nan
    return float(np.mean(entry_meta(entry)["seconds_per_view"]))


def make_row(
    ident: dict, scores: dict, timing: dict[str, float], failure: str | None, render_s: float
) -> dict:
    row = {
        **ident,
        **scores,
        "render_s_per_view": render_s,
        **{f"{k}_ms": 1000 * v for k, v in timing.items()},
        "wall_ms": 1000 * sum(v for k, v in timing.items() if not k.startswith("evaluate")),
        "status": "ok" if failure is None else "failed",
        "failure": failure or "",
    }
    if failure:  # a failed task's model has no points to measure (`Metric.of_model`)
        row |= {k: math.nan for k in row if k in METRICS and METRICS[k].of_model}
    return row
