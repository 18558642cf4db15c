"""Executing the units of the grid: in this process (`--workers 1`) or on Dask (a local
cluster of N single-threaded worker processes, or an existing cluster by address).

Units of work, with their dependencies: the front end of each (scene, seed), after its
render (one per geometry its tasks grant); then each unit, which waits for its scene's
front end, predicts (`bench.unit.predict`; skipped when it only re-scores a current
stored prediction) and scores (`bench.unit.evaluate`). Renders come first, from the main
process: with N local workers, N scenes side by side, each in a process of its own
(`bench.render.entry.render_scenes`: Mitsuba's LLVM variant uses every core and the CUDA
variant the GPU, and the developing step of one scene runs while another is traced).
Each worker process holds one thread per library (`bench.harness.workers`). Units are
submitted scene by scene, the costliest of each scene first (`largest_first`). A worker
holds one scene at a time (`_scene`; a dataset's bag, `Unit.bag`, is a scene of its own,
`bench.unit.bags`). Rows come
back to the main process, which alone writes `runs.csv`. A method that fails (its policy
raises or breaks the contract: `bench.MethodFailed`) is a value, in process as on a worker: the
unit's rows are recorded as failed, saying what and where, and the grid goes on. A unit
whose worker dies is retried once, then recorded the same way. The failure of such a row
starts with `ERROR` (a task's outcome, such as a mapper that registered no view, does not).
A `BenchError` (bad input, deterministic) comes back as a value, is not retried, and stops
the run as it does in process. The workers of a local cluster ignore Ctrl-C and SIGTERM
(sent to the whole process group by a terminal, `timeout` or systemd), which the main
process handles by stopping them. With a cluster given by address, the workers must see the same `renders/`
and results folder (a shared file system).

Every unit computes the same numbers wherever it runs: its inputs are files and
settings, its generators are seeded per unit, and COLMAP runs single-threaded and seeded.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

from bench import BenchError, MethodFailed
from bench.evaluation.truth import scene_truth
from bench.failures import ERROR
from bench.frontend import plugins
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import RIG
from bench.frontend.selection import check_budgets
from bench.frontend.stage import FrontEnd, bag_front_end, front_end
from bench.frontend.views import load_views
from bench.harness.keys import unit_keys
from bench.results import Workspace
from bench.unit import bags
from bench.unit.config import RunConfig
from bench.unit.evaluate import identities
from bench.unit.methods import runner
from bench.unit.pooled import known
from bench.unit.predict import Keys, LoadedScene, has_prediction, predict
from bench.unit.tasks import TASK_RUNNERS
from bench.vocabulary import (
    GROUND_TRUTH,
    METHODS,
    MULTI_VIEW,
    OWN_PIPELINE,
    TRACKS_PEER,
    Job,
    Unit,
)

_HELD: dict = {}
"""The one scene this process holds."""


@dataclass(frozen=True)
class Work:
    """What a unit has to do: its jobs, and whether it only re-scores them."""

    jobs: tuple[Job, ...]
    rescore: bool = False
    """Score the stored prediction again; predict only where none is current."""


@dataclass(frozen=True)
class Plan:
    """The work of a run: render entry per (scene, seed) and work per unit."""

    entries: dict[tuple[str, int], Path]
    work: dict[Unit, Work]

    def budgets(self, cfg: RunConfig) -> dict[DetectorConfig, tuple[int, ...]]:
        """The budgets of its units that select from the front end's pools, by the
        detector of their pool (`RunConfig.for_method`; not a peer's budgets, which
        extracts a pool of its own)."""
        own = {m for m, d in METHODS.items() if d.kind in (OWN_PIPELINE, TRACKS_PEER)}
        out: dict[DetectorConfig, set[int]] = {}
        for u in self.work:
            det = cfg.for_method(known(u.method)).detector
            out.setdefault(det, set()).update(
                [u.budget] if u.budget > 0 and u.method not in own else []
            )
        return {det: tuple(sorted(b)) for det, b in out.items()}

    @property
    def grants(self) -> tuple[str, ...]:
        return tuple(
            sorted({TASK_RUNNERS[j.task].spec.grant for w in self.work.values() for j in w.jobs})
        )


@dataclass(frozen=True)
class Cluster:
    """Where units run: `workers` local processes (1: this process), or a scheduler."""

    workers: int = 1
    scheduler: str | None = None


def _front_ends(
    entry: Path, cfg: RunConfig, renders: Path, grants, bag: str = ""
) -> tuple[dict[str, FrontEnd], dict[str, FrontEnd]]:
    """The front end of an entry under each geometry granted, computed or read from its
    cache, and the one its units read: of a bag of some of its views (`bench.unit.bags`),
    the bag's views alone, from what the whole's front end takes of it, each cached."""
    views = load_views(entry)  # decoded once, when a front end is computed
    keep = bags.bag_views(views, bag)
    det, sig, cache = cfg.detector, cfg.signals, renders / "frontend"
    whole = {g: front_end(entry, det, sig, cache, g, views, bool(keep)) for g in grants}
    if not keep:
        return whole, whole
    return whole, {g: bag_front_end(entry, det, sig, cache, g, fe, keep) for g, fe in whole.items()}


def _scene(entry: Path, cfg: RunConfig, renders: Path, grants, bag: str = "") -> LoadedScene:
    key = (str(entry), repr(cfg.detector), repr(cfg.signals), tuple(grants), bag)
    if _HELD.get("key") != key:
        _HELD.clear()  # let the previous scene go before loading the next
        whole, fronts = _front_ends(entry, cfg, renders, grants, bag)
        if fronts is not whole:  # a bag's views alone
            truth = bags.bag_truth(entry, fronts)
        else:  # the evaluation side may read the poses: the rig's front end holds them
            posed = fronts[RIG].views if RIG in fronts else load_views(entry)
            cams, names = [v.camera for v in posed], [v.name for v in posed]
            truth = scene_truth(entry, cams, names, next(iter(fronts.values())).pools)
        _HELD.update(key=key, scene=LoadedScene(entry, fronts, truth))
    return _HELD["scene"]


def scene_task(group: tuple, entry: Path, cfg: RunConfig, renders: Path, plan: Plan) -> dict:
    """The front ends of the render entry of `group` (scene, seed) under each geometry
    granted (and of its bag), of each pool its units select from, computed or read from
    their cache, checked against the budgets; returns their seconds and the largest pool."""
    t = time.perf_counter()
    plugins.load(cfg.policy.modules)  # the pools and policies from outside, on a worker
    bag = next((u.bag for u in plan.work if u.group == group), "")
    largest = 0
    for det, budgets in plan.budgets(cfg).items():
        whole, _ = _front_ends(entry, replace(cfg, detector=det), renders, plan.grants, bag)
        sizes = [len(p) for p in next(iter(whole.values())).pools]
        check_budgets(sizes, budgets, f"{group[0]} seed {group[1]}, {det.detector} pool")
        largest = max(largest, *sizes)
    return {"seconds": time.perf_counter() - t, "largest_pool": largest}


def compute_unit(
    scene: LoadedScene, unit: Unit, work: Work, cfg: RunConfig, ws: Workspace
) -> list[dict]:
    """The rows of one unit: predicted (unless it only re-scores a current prediction),
    then scored; failed rows saying where, if its policy fails."""
    plugins.load(cfg.policy.modules)  # in a worker process, the policies from outside
    jobs, run, keys = list(work.jobs), runner(unit.method), unit_keys(cfg, unit.method)
    try:
        if not (work.rescore and has_prediction(ws, unit, jobs, keys)):
            predict(scene, unit, jobs, cfg, ws, run.store, keys)
    except MethodFailed as e:
        tasks = ", ".join(e.tasks) or "?"
        why = f"{e} in {unit.scene} seed {unit.seed}, task {tasks}"
        return failed_rows(scene.entry, unit, jobs, keys, why)
    return run.score(scene, unit, jobs, cfg, ws, run.read, keys)


def unit_task(unit: Unit, plan: Plan, cfg: RunConfig, ws: Workspace, *_after) -> list[dict]:
    """The rows of one unit of a plan, on its pool (`_after`: what it waits for)."""
    plugins.load(cfg.policy.modules)  # in a worker process, the policies from outside
    cfg = cfg.for_method(known(unit.method))
    scene = _scene(plan.entries[unit.group], cfg, ws.renders, plan.grants, unit.bag)
    return compute_unit(scene, unit, plan.work[unit], cfg, ws)


def failed_rows(entry: Path, unit: Unit, jobs, keys: Keys, why: str) -> list[dict]:
    """Rows recording a unit that could not be computed (their failure: `ERROR` + why),
    with no value for any metric a task needs (so a report of such rows alone is drawn)."""
    failure = ERROR + " ".join(why.split())[:400]
    empty = {k: math.nan for r in TASK_RUNNERS.values() for k in r.spec.needs}
    return [
        ident | empty | {"wall_ms": math.nan, "status": "failed", "failure": failure}
        for ident in identities(entry, unit, jobs, keys)
    ]


OnScene = Callable[[tuple[str, int], dict], None]


def execute(
    plan: Plan, cfg: RunConfig, ws: Workspace, cluster: Cluster, on_scene: OnScene
) -> Iterator[list[dict]]:
    """Yield the rows of each unit as it finishes; `on_scene(group, info)` is told when a
    scene's front end is ready."""
    ws = Workspace(Path(ws.results).resolve(), Path(ws.renders).resolve())
    if cluster.workers == 1 and cluster.scheduler is None:
        for group, entry in plan.entries.items():
            on_scene(group, scene_task(group, entry, cfg, ws.renders, plan))
            for unit in (u for u in plan.work if u.group == group):
                yield unit_task(unit, plan, cfg, ws)
        _HELD.clear()
        return
    yield from _on_dask(plan, cfg, ws, cluster, on_scene)


def unit_size(unit: Unit, work: Work) -> tuple:
    """A unit's expected cost, as a sort key (larger: costlier), from what it is: a
    whole-pool unit (`all`, stock COLMAP), then a stock-COLMAP peer and the ground-truth
    selection (each runs a pipeline of its own, or reads every candidate's track), then
    the feedback loop (matches each round), then the rest; within each, by budget and jobs.
    (Measured on the published dense rows: `all` 40 s a unit, `colmap` 42 s, the COLMAP
    peers 20-27 s, the oracle 24-30 s, the loop 3-12 s, the other policies 1-7 s.)"""
    method = METHODS[unit.method]
    heavy = {OWN_PIPELINE: 2, TRACKS_PEER: 2, GROUND_TRUTH: 2, MULTI_VIEW: 1}.get(method.kind, 0)
    return (3 if method.whole_pool else heavy, unit.budget, len(work.jobs))


def largest_first(plan: Plan) -> list[Unit]:
    """The units of a plan, scene by scene as the plan holds them and pool by pool (a
    worker keeps the scene it holds: `_scene`), the costliest of each first (`unit_size`),
    so that the run does not end waiting on one large unit started last."""
    groups = list(plan.entries)
    return sorted(
        plan.work,
        key=lambda u: (
            groups.index(u.group),
            METHODS[u.method].pool,
            tuple(-x for x in unit_size(u, plan.work[u])),
        ),
    )


def _as_value(task, *args):
    """Run a task on a worker; bad input (a `BenchError`, deterministic) comes back as a
    value, so it is neither retried nor printed with a worker's traceback."""
    try:
        return task(*args)
    except BenchError as e:
        return e


def _result(future):
    """A finished future's result; bad input returned by `_as_value` is raised here."""
    out = future.result()
    if isinstance(out, BenchError):
        raise out
    return out


def _local_cluster(workers: int):
    """A local cluster of single-threaded worker processes that start with Ctrl-C ignored
    (it reaches this process alone, which stops them), are set up before they take work
    (`bench.harness.workers`: SIGTERM ignored too) and log only critical errors. No
    dashboard; the scheduler's HTTP server (Dask's health and metrics routes) takes a free
    port of this machine's own, not 8787, so nobody is told that 8787 is in use."""
    import logging

    from distributed import LocalCluster

    from bench.harness.workers import WorkerSetup

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the workers
    try:
        return LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.CRITICAL,
            plugins={WorkerSetup()},
        )
    finally:
        signal.signal(signal.SIGINT, previous)


def check_scheduler(address: str) -> None:
    """Refuse, in one line and within seconds, a Dask scheduler that cannot be reached.

    The scheduler is asked for its identity over one connection, in an event loop of
    this call's own that is closed before it returns. No `Client` is made: one that fails
    half-built is left for the garbage collector, whose clean-up then deadlocks the next
    client started in this process (on `distributed`'s `LoopRunner` lock).
    """
    import asyncio

    from distributed.comm import connect

    async def identity():
        comm = await connect(address, timeout="10s")
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            await comm.close()

    try:
        reply = asyncio.run(asyncio.wait_for(identity(), 20))
    except TimeoutError:
        why = "no answer within 20 s"
    except (OSError, ValueError, TypeError) as e:
        why = str(e)
    else:
        if isinstance(reply, dict) and str(reply.get("type")).endswith("Scheduler"):
            return
        why = "it answers, but is not a Dask scheduler"
    raise BenchError(f"cannot reach the Dask scheduler {address}: {why}")


def _start(cluster: Cluster, plan: Plan):
    """A client of the cluster, the local cluster it starts (None with a scheduler), and
    the plan sent to every worker. A SIGTERM meanwhile is held until they are, then acted
    on once both are closed: stopped half-started, distributed's exit hook failed on the
    workers still starting (`AssertionError: Status.init`), and a scatter on the
    scheduler on the workers gone (`KeyError`), each a traceback after the run's last line."""
    from distributed import Client

    held, failed = [], None
    previous = signal.getsignal(signal.SIGTERM)
    if previous is not signal.SIG_IGN:  # one ignored stays ignored
        signal.signal(signal.SIGTERM, lambda signum, frame: held.append(signum))
    local = client = shared = None
    try:
        local = _local_cluster(cluster.workers) if cluster.scheduler is None else None
        client = Client(cluster.scheduler or local, timeout="10s")
        shared = client.scatter(plan, broadcast=True)  # sent once, not with every unit
    except BaseException as e:  # raised again below, unless a SIGTERM held stops the run
        failed = e
    finally:  # None: a handler not set from Python, which cannot be set back
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    try:
        if held:
            signal.raise_signal(signal.SIGTERM)  # for the handler before, now
        if failed is not None:
            raise failed
    except BaseException:
        _disconnect(client, local)
        raise
    return client, local, shared


def _disconnect(client, local) -> None:
    """Close a client and the local cluster it started, either of them None."""
    if client is not None:
        client.close()
    if local is not None:
        local.close()


def _on_dask(plan: Plan, cfg: RunConfig, ws: Workspace, cluster: Cluster, on_scene: OnScene):
    from distributed import as_completed

    client, local, shared = _start(cluster, plan)
    try:
        fronts = {
            client.submit(
                _as_value, scene_task, group, entry, cfg, ws.renders, shared, pure=False
            ): group
            for group, entry in plan.entries.items()
        }
        by_group = {g: f for f, g in fronts.items()}
        order = largest_first(plan)
        pending = {
            client.submit(
                _as_value,
                unit_task,
                unit,
                shared,
                cfg,
                ws,
                by_group[unit.group],
                retries=1,
                pure=False,
                priority=len(order) - k,  # Dask runs the higher first
            ): unit
            for k, unit in enumerate(order)
        }
        for future in as_completed([*fronts, *pending]):
            if future in fronts:
                exc = future.exception()
                if exc is not None:
                    raise BenchError(
                        f"front end of {fronts[future]} failed: {type(exc).__name__}: {exc}"
                    )
                on_scene(fronts[future], _result(future))
                continue
            unit = pending[future]
            exc = future.exception()
            if exc is not None:
                why = f"failed on a worker, retried once: {type(exc).__name__}: {exc}"
                keys = unit_keys(cfg, unit.method)
                yield failed_rows(plan.entries[unit.group], unit, plan.work[unit].jobs, keys, why)
            else:
                yield _result(future)
    finally:
        _disconnect(client, local)


def default_workers() -> int:
    """One worker per core."""
    return os.cpu_count() or 1
