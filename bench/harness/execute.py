"""Executing the units of the grid: in this process (`--workers 1`) or on Dask (a local
cluster of N single-threaded worker processes, or an existing cluster by address).

Units of work, with their dependencies: the front end of each (scene, seed), after its
render (one per geometry its tasks grant); then each (scene, seed, policy, budget) unit,
which waits for its scene's front end. Renders stay in the main process, so one process
renders per machine (Mitsuba's LLVM and CUDA variants use every core, or the GPU, on
their own). A worker holds one scene's front ends and ground truth at a time (`_scene`).
Rows come back to the main process, which alone writes `runs.csv`. A unit whose worker
dies is retried once, then recorded as failed rows with the reason; a `BenchError` (bad
input, deterministic) comes back as a value, is not retried, and stops the run as it does
in process. The workers of a local cluster ignore Ctrl-C, which the main process handles
by stopping them. With a cluster given by address, the workers must see the same
`renders/` and results folder (a shared file system).

Every unit computes the same numbers wherever it runs: its inputs are files and
settings, its generators are seeded per unit, and COLMAP runs single-threaded and seeded.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

from bench import BenchError
from bench.backend.peers import PEERS
from bench.evaluation.metrics import load_truth
from bench.frontend.geometry import RIG
from bench.frontend.stage import FrontEnd, front_end
from bench.frontend.views import load_views
from bench.harness.pipeline import GRANTS, RunConfig, row_identity, run_peer_unit, run_unit

_HELD: dict = {}
"""The one scene (front end and ground truth) this process holds."""


def _front_ends(entry: Path, cfg: RunConfig, renders: Path, grants) -> dict[str, FrontEnd]:
    """The front end of an entry under each geometry granted, computed or read from its cache."""
    return {g: front_end(entry, cfg.detector, cfg.signals, renders / "frontend", g) for g in grants}


def _scene(entry: Path, cfg: RunConfig, renders: Path, grants):
    key = (str(entry), cfg.hash, tuple(grants))
    if _HELD.get("key") != key:
        _HELD.clear()  # let the previous scene go before loading the next
        fronts = _front_ends(entry, cfg, renders, grants)
        # the evaluation side may read the poses: the rig's front end holds them
        posed = fronts[RIG].views if RIG in fronts else load_views(entry)
        cams, names = [v.camera for v in posed], [v.name for v in posed]
        truth = load_truth(entry, cams, names, next(iter(fronts.values())).pools)
        _HELD.update(key=key, fronts=fronts, truth=truth)
    return _HELD["fronts"], _HELD["truth"]


def scene_task(group: tuple, entry: Path, cfg: RunConfig, renders: Path, budgets, grants) -> dict:
    """The front ends of the render entry of `group` (scene, seed) under each geometry
    granted, computed or read from their cache, checked against the budgets; returns their
    seconds and the largest pool."""
    t = time.perf_counter()
    fronts = _front_ends(entry, cfg, renders, grants)
    largest = max(len(p) for p in next(iter(fronts.values())).pools)
    if largest == 0:
        raise BenchError(
            f"the detector found no candidate in any view of {group[0]} seed {group[1]}; "
            "the images are too small or too flat for it (try a larger --width/--height)"
        )
    too_big = [b for b in budgets if b > largest]
    if too_big:
        raise BenchError(
            f"budget {too_big[0]} exceeds every candidate pool of {group[0]} seed {group[1]} "
            f"(the largest has {largest}); every policy would select the whole pool. "
            f"Use budgets up to {largest}"
        )
    return {"seconds": time.perf_counter() - t, "largest_pool": largest}


def unit_task(
    entry: Path,
    unit: tuple,
    jobs: list,
    cfg: RunConfig,
    results: Path,
    renders: Path,
    grants,
    *_after,
) -> list[dict]:
    """The rows of one (scene, seed, policy, budget) unit (`_after`: what it waits for)."""
    scene, seed, policy, budget = unit
    fronts, truth = _scene(entry, cfg, renders, grants)
    args = (entry, fronts, truth, scene, seed, policy, budget, jobs, cfg, results)
    return run_peer_unit(*args) if policy in PEERS else run_unit(*args)


def failed_rows(entry: Path, unit: tuple, jobs: list, cfg: RunConfig, why: str) -> list[dict]:
    """Rows recording a unit that could not be computed."""
    return [
        row_identity((entry, *unit, task, protocol, cfg))
        | {"wall_ms": math.nan, "status": "failed", "failure": why}
        for task, protocol in jobs
    ]


def execute(
    scenes: dict[tuple, Path],
    units: dict[tuple, list],
    cfg: RunConfig,
    budgets,
    results: Path,
    renders: Path,
    workers: int,
    scheduler: str | None,
    on_scene,
) -> Iterator[list[dict]]:
    """Yield the rows of each unit as it finishes. `scenes`: render entry per (scene,
    seed); `units`: jobs per unit; `on_scene(group, info)` is told when a front end is ready."""
    results, renders = Path(results).resolve(), Path(renders).resolve()
    grants = tuple(sorted({GRANTS[task] for jobs in units.values() for task, _ in jobs}))
    if workers == 1 and scheduler is None:
        for group, entry in scenes.items():
            on_scene(group, scene_task(group, entry, cfg, renders, budgets, grants))
            for unit, jobs in ((u, j) for u, j in units.items() if u[:2] == group):
                yield unit_task(entry, unit, jobs, cfg, results, renders, grants)
        _HELD.clear()
        return
    yield from _on_dask(
        scenes, units, cfg, budgets, results, renders, workers, scheduler, on_scene, grants
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
    (it reaches this process alone, which stops them) and log only critical errors."""
    import logging

    from distributed import LocalCluster

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the workers
    try:
        return LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.CRITICAL,
        )
    finally:
        signal.signal(signal.SIGINT, previous)


def check_scheduler(address: str) -> None:
    """Refuse, in one line and within seconds, a Dask scheduler that cannot be reached."""
    from distributed import Client

    try:
        Client(address, timeout="10s").close()
    except (OSError, ValueError, TypeError) as e:
        raise BenchError(f"cannot reach the Dask scheduler {address}: {e}") from None


def _on_dask(scenes, units, cfg, budgets, results, renders, workers, scheduler, on_scene, grants):
    from distributed import Client, as_completed

    cluster = _local_cluster(workers) if scheduler is None else None
    client = Client(scheduler or cluster, timeout="10s")
    try:
        fronts = {
            client.submit(
                _as_value, scene_task, group, entry, cfg, renders, budgets, grants, pure=False
            ): group
            for group, entry in scenes.items()
        }
        by_group = {g: f for f, g in fronts.items()}
        pending = {
            client.submit(
                _as_value,
                unit_task,
                scenes[u[:2]],
                u,
                jobs,
                cfg,
                results,
                renders,
                grants,
                by_group[u[:2]],
                retries=1,
                pure=False,
            ): (u, jobs)
            for u, jobs in units.items()
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
            unit, jobs = pending[future]
            exc = future.exception()
            if exc is not None:
                why = f"failed on a worker, retried once: {type(exc).__name__}: {exc}"
                yield failed_rows(scenes[unit[:2]], unit, jobs, cfg, why.replace("\n", " ")[:300])
            else:
                yield _result(future)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def default_workers() -> int:
    """One worker per core."""
    return os.cpu_count() or 1
