"""One unit of work up to its reconstructions, stored as the unit's prediction.

render entry -> front end (cached) under the geometry each task grants -> selection of B
per view (a policy, or the oracle, which reads ground truth as a reference) -> match ->
verify -> for each job (task, protocol): reconstruct (COLMAP) -> export the model. The
jobs of one grant share the selection, matching and verification, so they see exactly
the same matches; a selection that does not depend on the grant (it reads no geometry)
is matched once for both. A stock-COLMAP peer extracts, matches and maps on its own; a
learned peer (`aliked-b`) selects and matches like a policy, with LightGlue.

What a unit predicted is stored in its folder (`Workspace.unit_dir`): the selections and
verified matches (`prediction-<grant>.npz`, a peer's keypoints in `prediction-peer.npz`),
the models exported per job, and `prediction.json` (written last: the view names, each
stage's seconds, each job's prediction hash and failure). `bench.unit.evaluate`
scores it; nothing here scores.

The arrays, by key: `prediction-<grant>.npz` holds `selection_{v}` (the indices into view
v's candidate pool that the policy selected, ascending) and, for the k-th pair of
`prediction.json`'s `grants[<grant>]["pairs"]` (views i < j, COLMAP's two-view
configuration), `tentative_{k}` and `verified_{k}` (matches as (M, 2) rows of indices into
the selections of views i and j) and, where the verification estimated one, `pose_{k}`
(the relative pose [R | t], (3, 4), of view j's camera from view i's, unit t: what the
`pairs` task scores); `prediction-peer.npz` holds `keypoints_{v}` (the (N, 2) pixel
positions of the peer's keypoints in view v, as COLMAP's database holds them) and
`pose_{k}` of the k-th pair of `prediction.json`'s `peer["pairs"]`. `prediction.json`'s `jobs` are keyed by `Job.key` (`<task>/<protocol>`).
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from bench import MethodFailed
from bench.backend.matching import PairMatches
from bench.backend.peers import CAPS, COLMAP_SIFT, TRACKS, peer_extraction, run_peer
from bench.evaluation.oracle import matchable_tracks, oracle_select
from bench.evaluation.truth import SceneTruth
from bench.files import atomic_path, temp_dir_beside, write_text_atomic
from bench.frontend.stage import FrontEnd
from bench.frontend.views import Source
from bench.results import LOOP, PREDICTION, Workspace
from bench.unit import select_match
from bench.unit.config import RunConfig
from bench.unit.tasks import TASK_RUNNERS, Matched
from bench.vocabulary import Job, Unit


@dataclass(frozen=True)
class LoadedScene:
    """One scene and seed as a unit reads it: its render entry (or dataset), its front end
    under each geometry granted, and its ground truth (the evaluation side's)."""

    entry: Path
    fronts: dict[str, FrontEnd]
    truth: SceneTruth


@dataclass(frozen=True)
class Keys:
    """The keys a unit's rows carry, computed by the harness (`bench.harness.keys`) and
    handed in: nothing in the unit hashes code, libraries or settings."""

    prediction: Callable[[str], str]
    """A task -> the `prediction_hash` of the unit's method's rows of that task (what a
    stored job records, and what makes it current)."""
    evaluation: str
    """The `evaluation_hash` of every row."""
    columns: dict[str, str] = field(default_factory=dict)
    """What else names its rows: their pool and matcher (`bench.unit.pooled.row_pool`)."""


def current(job: dict, keys: Keys, task: str) -> bool:
    """Whether a job's stored prediction (its record in `prediction.json`) is current: its
    hash is this code's, libraries' and settings' (`keys`)."""
    return job.get("hash") == keys.prediction(task)


Selection = tuple[list[np.ndarray], list[dict]]
"""Every view's selection (indices into its pool) and a multi-view policy's rounds."""


def policy_selection(fe: FrontEnd, truth: SceneTruth, unit: Unit, cfg: RunConfig) -> Selection:
    """A policy's selection (`bench.frontend.selection`; it never sees `truth`)."""
    selections, rounds, _ = select_match.select(fe.views, fe.pools, fe.signals, unit, cfg)
    return selections, rounds


def oracle_selection(fe: FrontEnd, truth: SceneTruth, unit: Unit, cfg: RunConfig) -> Selection:
    """The ground-truth selection (`bench.evaluation.oracle`): a reference."""
    found = matchable_tracks(truth, fe.pools, cfg.backend.ratio)
    return oracle_select(found, [c.response for c in fe.pools], unit.budget), []


MODEL_FILES = ("cameras.txt", "images.txt", "points3D.txt", "rigs.txt", "frames.txt", "points.ply")
"""The files of an exported model (a unit's folder holds more: its prediction, loop.json,
the models of its other jobs)."""


def export_model(model, out: Path) -> None:
    """COLMAP text model + points.ply into `out`: written in a temporary folder beside it,
    then each file renamed into place, the files of an earlier model removed first."""
    out.mkdir(parents=True, exist_ok=True)
    scratch = temp_dir_beside(out)
    try:
        model.write_text(str(scratch))
        model.export_PLY(str(scratch / "points.ply"))
        for name in MODEL_FILES:
            (out / name).unlink(missing_ok=True)
        for f in sorted(scratch.iterdir()):
            with atomic_path(out / f.name) as tmp:
                shutil.move(f, tmp)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def clear_model(out: Path) -> None:
    """Remove an exported model's files (and its folder, if nothing else is left there)."""
    for name in MODEL_FILES:
        (out / name).unlink(missing_ok=True)
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def _export_or_clear(model, out: Path) -> None:
    """Export a model; without one, remove what an earlier run left there."""
    if model is not None:
        export_model(model, out)
    else:
        clear_model(out)


Store = Callable[[LoadedScene, Unit, list[Job], RunConfig, Workspace, dict], None]
"""How a kind of method computes and stores a unit's prediction, filling its record
(`bench.unit.methods`)."""


def predict(
    scene: LoadedScene,
    unit: Unit,
    jobs: list[Job],
    cfg: RunConfig,
    ws: Workspace,
    store: Store,
    keys: Keys,
) -> None:
    """Compute and store the prediction of `unit` for `jobs` with its kind's `store`
    (module docstring)."""
    folder = ws.unit_dir(unit)
    folder.mkdir(parents=True, exist_ok=True)
    record = {"grants": {}, "jobs": {}}
    earlier = read_record(folder)
    kept = {  # the earlier jobs of other tasks or protocols that are still current
        k: j
        for k, j in job_records(earlier).items()
        if k not in {j.key for j in jobs}
        and k.partition("/")[0] in TASK_RUNNERS
        and current(j, keys, k.partition("/")[0])
    }
    if kept:
        record |= {k: earlier[k] for k in ("grants", "peer") if k in earlier}
        record["jobs"] = kept
    store(scene, unit, jobs, cfg, ws, record)
    for job in jobs:
        record["jobs"][job.key]["hash"] = keys.prediction(job.task)
    write_text_atomic(folder / f"{PREDICTION}.json", json.dumps(record, indent=1))


def store_selection(select: Callable[..., Selection]) -> Store:
    """The `Store` of a method that selects from the pools with `select` (a policy, the
    oracle): the selection matched and verified by the back end, then each job's task."""
    return partial(_store_selection, select=select)


def _store_selection(scene, unit, jobs, cfg, ws, record, select) -> None:
    folder, matched = ws.unit_dir(unit), {}
    for grant in dict.fromkeys(TASK_RUNNERS[j.task].spec.grant for j in jobs):
        fe = scene.fronts[grant]
        try:
            t = time.perf_counter()
            selections, rounds = select(fe, scene.truth, unit, cfg)
            select_s = time.perf_counter() - t
        except MethodFailed as e:
            e.tasks = tuple(
                dict.fromkeys(j.task for j in jobs if TASK_RUNNERS[j.task].spec.grant == grant)
            )
            raise
        key = repr(([s.tolist() for s in selections], rounds))
        xy = [c.xy[s] for c, s in zip(fe.pools, selections)]
        if key not in matched:
            cams = [v.camera for v in fe.views]
            matched[key] = select_match.match(cams, fe.pools, selections, unit.method, cfg)
        pairs, match_s = matched[key]
        record["names"] = [v.name for v in fe.views]
        record["grants"][grant] = {
            "seconds": {"select": select_s, **match_s},
            "rounds": rounds,
            "pairs": [{"i": p.i, "j": p.j, "config": p.config} for p in pairs],
        }
        arrays = {f"selection_{v}": s for v, s in enumerate(selections)}
        for k, p in enumerate(pairs):
            arrays |= {f"tentative_{k}": p.tentative, f"verified_{k}": p.verified}
        arrays |= pose_arrays(pairs)
        with atomic_path(folder / f"{PREDICTION}-{grant}.npz") as tmp:
            np.savez(tmp, **arrays)
        m = Matched([v.camera for v in fe.views], record["names"], xy, pairs)
        grant_jobs = [j for j in jobs if TASK_RUNNERS[j.task].spec.grant == grant]
        for job in grant_jobs:
            runner = TASK_RUNNERS[job.task]
            rec = runner.reconstruct(m, cfg.backend, job.protocol)
            model = rec.model
            if model is None and runner.record is not None:
                model = runner.record(m)  # the exported model still records the selection
            _export_or_clear(model, ws.model_dir(unit, job))
            record["jobs"][job.key] = {
                "grant": grant,
                "failure": rec.failure,
                "task_s": rec.seconds,
                "model": model is not None,
            }
        if rounds:
            loop = ws.model_dir(unit, grant_jobs[0])
            loop.mkdir(parents=True, exist_ok=True)
            write_text_atomic(loop / LOOP, json.dumps(rounds, indent=1))


def store_own_pipeline(scene, unit, jobs, cfg, ws, record) -> None:
    """The `Store` of a method with a pipeline of its own (stock COLMAP): it maps its own database for a task that maps (`TaskRunner.maps`); a task that
    does not is given the peer's keypoints and verified pairs, with their poses."""
    fe = next(iter(scene.fronts.values()))
    names, cams = [v.name for v in fe.views], [v.camera for v in fe.views]
    image_dir = Source.of(scene.entry).images
    mapped = list(dict.fromkeys(j.protocol for j in jobs if TASK_RUNNERS[j.task].maps))
    sift = ws.renders / COLMAP_SIFT
    extracted = peer_extraction(image_dir, names, cams, unit.method, unit.budget, sift)
    keep_tracks = unit.budget if CAPS[unit.method] == TRACKS else 0
    run = run_peer(names, cams, extracted, cfg.backend, mapped, keep_tracks)
    record["names"] = names
    record["peer"] = {
        "tentative": run.tentative,
        "verified": run.verified,
        "seconds": run.seconds,
        "pairs": [{"i": p.i, "j": p.j, "config": p.config} for p in run.pairs],
    }
    arrays = {f"keypoints_{v}": k for v, k in enumerate(run.keypoints)} | pose_arrays(run.pairs)
    with atomic_path(ws.unit_dir(unit) / f"{PREDICTION}-peer.npz") as tmp:
        np.savez(tmp, **arrays)
    matched = Matched(cams, names, run.keypoints, run.pairs)
    for job in jobs:
        runner = TASK_RUNNERS[job.task]
        if runner.maps:
            rec, extra_s = run.recs[job.protocol], 0.0
        else:
            rec, extra_s = runner.reconstruct(matched, cfg.backend, job.protocol), run.pose_s
        _export_or_clear(rec.model, ws.model_dir(unit, job))
        record["jobs"][job.key] = {
            "grant": "peer",
            "failure": rec.failure,
            "task_s": rec.seconds + extra_s,
            "model": rec.model is not None,
        }


def read_record(folder: Path) -> dict:
    """A unit's `prediction.json`, or {} if there is none (or it is unreadable)."""
    try:
        return json.loads((folder / f"{PREDICTION}.json").read_text())
    except (OSError, ValueError):
        return {}


def job_records(record: dict) -> dict[str, dict]:
    """A record's jobs, each with its prediction hash (a record of the code before hashes
    per job: the unit's)."""
    unit = {"hash": record["hash"]} if "hash" in record else {}
    return {k: unit | j for k, j in record.get("jobs", {}).items()}


def has_prediction(ws: Workspace, unit: Unit, jobs: list[Job], keys: Keys) -> bool:
    """Whether the unit's folder holds a current prediction of every job in `jobs`."""
    done = job_records(read_record(ws.unit_dir(unit)))
    return all(j.key in done and current(done[j.key], keys, j.task) for j in jobs)


def pose_arrays(pairs: list[PairMatches]) -> dict[str, np.ndarray]:
    """`pose_{k}` of the k-th pair, for the pairs with a relative pose."""
    return {f"pose_{k}": p.pose for k, p in enumerate(pairs) if p.pose is not None}


def stored_poses(pairs: list[dict], arrays) -> dict[tuple[int, int], np.ndarray]:
    """{(i, j): [R | t]} of the stored pairs (`pairs`: their records) with a pose."""
    return {
        (p["i"], p["j"]): arrays[f"pose_{k}"] for k, p in enumerate(pairs) if f"pose_{k}" in arrays
    }


def stored_pairs(record: dict, grant: str, arrays) -> list[PairMatches]:
    """The verified pairs of a grant's stored prediction."""
    return [
        PairMatches(p["i"], p["j"], arrays[f"tentative_{k}"], arrays[f"verified_{k}"], p["config"])
        for k, p in enumerate(record["grants"][grant]["pairs"])
    ]
