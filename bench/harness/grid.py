"""`bench run`: every unit of the grid, resumable and reproducible.

Stages per (scene, seed): render (cached) -> front end (cached) -> for each policy and
budget: one unit (`bench.harness.execute`), its rows appended to `runs.csv` at once (an
interrupt keeps every finished row; a cut last row is caught as damage, `bench.runs`).
The settings are stored in `config.json` beside the results and the vocabulary of the rows
in `vocabulary.json`; a run into a folder holding other settings is refused unless
`overwrite`. Rows whose prediction is current but whose scoring is not (or every row,
with `reevaluate`) are scored again from the stored predictions; rows computed on another
render entry (the scene's generator, parameters or render settings changed) or on a
dataset whose contents changed, and rows that could not be computed (a policy raised, a
worker died), are computed again. The last line says how many
of the grid's rows failed, by reason, and which (scene, seed) the sfm means leave out.
"""

from __future__ import annotations

import itertools
import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, astuple, dataclass, field
from functools import cached_property, partial
from pathlib import Path

import numpy as np
import pandas as pd

from bench import BenchError
from bench.binding import bind_results_dir, check_results_dir, models_replaced
from bench.codehash import check_unchanged, code_hash
from bench.console import log, progress
from bench.failures import ERROR, exclusions, failures, outcomes
from bench.frontend import plugins
from bench.frontend.matchability import read_models
from bench.frontend.policies import learned_weights
from bench.frontend.pools import POOLS, PoolSpec
from bench.frontend.views import pixels_key, source_key
from bench.harness.execute import Cluster, Plan, Work, check_scheduler, execute
from bench.harness.keys import PREDICTION_CODE, evaluation_hash, prediction_hash
from bench.harness.manifest import git_commit, write_manifest
from bench.render.config import RenderConfig
from bench.render.entry import (
    cached_entry,
    entry_names,
    known_pixels,
    render_scene,
    render_scenes,
)
from bench.results import DAMAGED, STALE, Workspace, holding
from bench.runs import (
    NO_PIXELS,
    append_runs,
    keep_runs,
    pixels_of,
    read_runs,
    set_aside_damaged,
)
from bench.scenes.spec import load_spec, scene_names
from bench.unit.bags import dataset_bags
from bench.unit.config import RunConfig
from bench.unit.pooled import SEPARATOR, known, own_spec, placement
from bench.unit.tasks import TASK_RUNNERS
from bench.vocabulary import (
    BAG,
    FRONTIER_PEERS,
    KEY,
    METHODS,
    NO_PROTOCOL,
    PROTOCOLS,
    REFERENCE_PEER,
    WHOLE_POOL_BUDGET,
    Job,
    Unit,
    Vocabulary,
)

_INVOCATIONS = itertools.count(1)
"""Numbers the invocations of this process: two in one second stay two (their id)."""


def default_methods() -> tuple[str, ...]:
    """Every method the package declares, in display order (not those of modules)."""
    vocab = Vocabulary.current()
    names = [n for n in METHODS if n not in plugins.ORIGIN and SEPARATOR not in n]
    return tuple(sorted(names, key=vocab.order))


def with_reference(methods: tuple[str, ...], tasks: tuple[str, ...]) -> tuple[str, ...]:
    """`methods`, with stock COLMAP with all features (`REFERENCE_PEER`) added when the
    grid runs a task with the exclusion rule (sfm) on rendered scenes: its means leave out
    the cells it does not map, and the rule holds only when it ran in every cell. (Said by
    `bench run --help`; the run's closing line names the cells it left out.)"""
    ruled = any(TASK_RUNNERS[t].spec.exclusion_reference for t in tasks if t in TASK_RUNNERS)
    if REFERENCE_PEER in methods or not ruled:
        return methods
    return (*methods, REFERENCE_PEER)


@dataclass(frozen=True)
class BenchConfig:
    """The benchmark grid and the configuration of every run in it."""

    scenes: tuple[str, ...] = field(default_factory=lambda: tuple(scene_names()))
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    methods: tuple[str, ...] = field(default_factory=default_methods)
    budgets: tuple[int, ...] = (128, 256, 512)
    tasks: tuple[str, ...] = field(
        default_factory=lambda: tuple(n for n, r in TASK_RUNNERS.items() if r.default)
    )
    """Default: every task but those run on request (`TaskRunner.default`: nbv)."""
    protocols: tuple[str, ...] = tuple(PROTOCOLS)
    run: RunConfig = field(default_factory=RunConfig)
    datasets: tuple[str, ...] = ()
    """Dataset folders (`bench run --dataset`) instead of rendered scenes: each is one
    scene, named by its folder; its seeds number its bags (`bag_size`)."""
    bag_size: int = 0
    """The images of a dataset's bag (`bench.unit.bags`); 0: the whole dataset, seed 0.
    A dataset's seeds are its bags' numbers, up to `max(seeds) + 1` bags."""
    frontier: tuple[int, ...] = ()
    """Budgets at which `FRONTIER_PEERS` alone run besides `budgets`: the cost figure's
    frontiers (a regime's grid: `FRONTIER_BUDGETS`)."""
    pools: tuple[str, ...] = ()
    """The pools its methods run on (`bench.unit.pooled`: `sift`, `aliked`,
    `aliked+ratio`, ...); empty: the run's own (`detector.detector`, `backend.matcher`)."""

    @cached_property
    def placed(self) -> tuple[tuple[str, ...], list[str]]:
        """The names of its methods on its pools, and a line for each method on none
        (`bench.unit.pooled.placement`)."""
        specs = tuple(PoolSpec.parse(p) for p in self.pools)
        return placement(self.methods, specs, own_spec(self.run))

    def _check_training_seeds(self) -> None:
        """Refuse evaluation seeds that a learned method's model was trained on."""
        trained = {}
        if "learned" in self.methods:
            own = self.run.policy_config("learned").learned_weights
            trained["learned weights", "train-weights"] = learned_weights(own)["seeds"]
        if "matchable" in self.methods:
            own = self.run.policy_config("matchable").matchability_model
            trained["matchability models", "train-matchability"] = read_models(own)["seeds"]
        for (what, command), seeds in trained.items():
            shared = sorted(set(seeds) & set(self.seeds))
            if shared:
                raise BenchError(
                    f"the {what} were trained on seed(s) {shared}, which are also "
                    f"evaluation seeds; evaluate on other seeds, or train on others "
                    f"(bench {command} --seeds ...)"
                )

    def validate(self) -> BenchConfig:
        if self.datasets:
            names = [Path(d).name for d in self.datasets]
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:
                raise BenchError(f"two datasets are named {twice[0]!r}; rename one folder")
            if sorted(self.scenes) != sorted(names):
                raise BenchError("the scenes of a dataset run are its datasets' names")
        else:
            for s in self.scenes:
                load_spec(s)
        plugins.load(self.run.policy.modules)
        for m in self.methods:
            known(m)
        for spec in self.pools:
            POOLS[PoolSpec.parse(spec).pool].require()
        if not self.datasets:
            self._check_training_seeds()
        unknown = [p for p in self.protocols if p not in PROTOCOLS]
        if unknown:
            raise BenchError(f"unknown protocol {unknown[0]!r}; valid: {', '.join(PROTOCOLS)}")
        unknown = [t for t in self.tasks if t not in TASK_RUNNERS]
        if unknown or not self.tasks:
            raise BenchError(
                f"unknown task {unknown[0] if unknown else ''!r}; valid: {', '.join(TASK_RUNNERS)}"
            )
        rigged = [t for t in self.tasks if TASK_RUNNERS[t].rig is not None]
        if rigged and len(self.tasks) > 1 and not self.datasets:
            raise BenchError(
                f"the {rigged[0]} task renders its own rig (the scene's planned path): run it "
                f"alone, --tasks {rigged[0]}"
            )
        if self.bag_size < 0 or self.bag_size == 1:
            raise BenchError(
                f"--bag-size must be 0 (the whole dataset) or at least 2, got {self.bag_size}"
            )
        if not self.seeds or min(self.seeds) < 0:
            raise BenchError(f"seeds must be non-negative integers, got {list(self.seeds)}")
        if not self.budgets or min((*self.budgets, *self.frontier)) <= 0:
            bad = ", ".join(str(b) for b in (*self.budgets, *self.frontier) if b <= 0) or "none"
            raise BenchError(
                f"--budget takes keypoints per view, each at least 1, got {bad} (a whole-pool "
                f"method's budget is {WHOLE_POOL_BUDGET})"
            )
        if not self.datasets:
            self.run.render.validate()
        self.run.validate()
        return self

    def as_dict(self) -> dict:
        return json.loads(json.dumps(asdict(self)))  # tuples as lists, as stored

    def dataset(self, scene: str) -> Path | None:
        """The folder of a dataset scene (None: a rendered scene)."""
        return next((Path(d) for d in self.datasets if Path(d).name == scene), None)

    def bags(self, scene: str) -> dict[int, str]:
        """The bags of a dataset scene by seed (`Unit.bag`, `bench.unit.bags`; none: a
        rendered scene, or a dataset scored whole)."""
        folder = self.dataset(scene)
        if folder is None or not self.bag_size:
            return {}
        drawn = dataset_bags(str(folder), self.bag_size, max(self.seeds) + 1)
        return dict(enumerate(drawn))

    def seeds_of(self, scene: str) -> tuple[int, ...]:
        """The seeds of a scene: a bagged dataset's are the numbers of the bags it has."""
        bags = self.bags(scene)
        return tuple(s for s in self.seeds if s in bags) if bags else self.seeds

    def units(self) -> list[Unit]:
        """Every unit of the grid that has a job; a whole-pool method (`all`, `colmap`)
        is one unit per scene and seed (of a bagged dataset, per bag), with budget 0."""
        bags = {sc: self.bags(sc) for sc in self.scenes}
        return [
            Unit(sc, sd, m, b, bags[sc].get(sd, ""))
            for sc in self.scenes
            for sd in self.seeds_of(sc)
            for m in self.placed[0]
            for b in self.budgets_of(m)
            if self.jobs(m)
        ]

    def budgets_of(self, method: str) -> tuple[int, ...]:
        """The budgets of a method's units: 0 for a whole-pool method; the grid's, and
        `frontier`'s for a frontier peer."""
        if METHODS[method].whole_pool:
            return (0,)
        more = self.frontier if method in FRONTIER_PEERS else ()
        return (*self.budgets, *(b for b in more if b not in self.budgets))

    def jobs(self, method: str) -> list[Job]:
        """Every job of a unit of `method`: the tasks its kind runs (`TaskRunner.kinds`;
        a peer runs the tasks that admit peers); a task without tracks (`Task.tracks`) one
        job, `NO_PROTOCOL`."""
        peer, kind = METHODS[method].role == "peer", METHODS[method].kind
        claimed = {k for r in TASK_RUNNERS.values() for k in r.kinds}
        tasks = [
            t
            for t in self.tasks
            if (TASK_RUNNERS[t].spec.peers or not peer)
            and (kind in TASK_RUNNERS[t].kinds if TASK_RUNNERS[t].kinds else kind not in claimed)
        ]
        return [Job(t, pr) for t in tasks for pr in self.protocols_of(t)]

    def protocols_of(self, task: str) -> tuple[str, ...]:
        """The protocols of a task's rows: the grid's, or `NO_PROTOCOL` without tracks."""
        return self.protocols if TASK_RUNNERS[task].spec.tracks else (NO_PROTOCOL,)

    def render(self, task: str | None = None) -> RenderConfig | None:
        """The render settings of the entries a task's units read (`TaskRunner.rig`; the
        grid's first task by default): the run's unless the task has its own rig."""
        rig = TASK_RUNNERS[task or self.tasks[0]].rig
        return self.run.render if rig is None or self.run.render is None else rig(self.run)


@dataclass(frozen=True)
class RunOptions:
    """How `run_benchmark` treats what the results folder already holds, and where it runs."""

    overwrite: bool = False
    """Replace results of other settings."""
    set_aside: bool = False
    """Move damaged rows to `runs.damaged.csv` and compute them again."""
    reevaluate: bool = False
    """Score every row of the grid again from its stored prediction."""
    cluster: Cluster = field(default_factory=Cluster)


Report = Callable[[pd.DataFrame, Path, Path], None]


def run_benchmark(
    cfg: BenchConfig,
    ws: Workspace,
    options: RunOptions = RunOptions(),
    report: Report | None = None,
) -> pd.DataFrame:
    """Run whatever of the grid is missing from `runs.csv`, then `report(rows, results,
    renders)` (see `bench.runs` and `bench.binding` for what counts as finished, damaged
    or refused). One run at a time holds a results folder; another is refused in one line
    while it does."""
    cfg.validate()
    if options.cluster.scheduler is not None:
        check_scheduler(options.cluster.scheduler)
    results = Path(ws.results)
    created = not results.exists()
    try:
        results.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(f"cannot write to {results}: {e.strerror}") from e
    try:
        with holding(results):
            return _run_in(cfg, ws, options, report)
    finally:
        if created and results.is_dir() and not any(results.iterdir()):
            results.rmdir()  # a refused run leaves no folder behind


def _current_rows(
    cfg: BenchConfig, ws: Workspace, options: RunOptions
) -> tuple[pd.DataFrame, pd.Series]:
    """The rows of `runs.csv` whose prediction is current, and which of them to score again."""
    vocab = Vocabulary.current()
    runs_csv = ws.runs_csv
    if options.set_aside and runs_csv.exists() and not options.overwrite:
        n = set_aside_damaged(runs_csv, vocab)
        log(f"{n} damaged row(s) of {runs_csv} set aside in {DAMAGED}")
    if not runs_csv.exists() or options.overwrite:
        df = pd.DataFrame(columns=[*KEY, "prediction_hash", "evaluation_hash", "render_key"])
        return df, pd.Series(False, index=df.index)
    df = read_runs(runs_csv, vocab, keep_altered=options.reevaluate)
    altered = df.pop("altered") if options.reevaluate else pd.Series(False, index=df.index)
    if altered.any():
        log(f"{int(altered.sum())} altered row(s) of {runs_csv}; scoring them again")
    # each row against its method's and task's hash; a method not registered now (a
    # module not given this time) keeps its rows as they are
    known = set(METHODS)
    hashes = {
        (m, t): prediction_hash(cfg.run, m, t)
        for m, t in set(zip(df["method"], df["task"]))
        if m in known and t in TASK_RUNNERS
    }
    stale = pd.Series(
        [
            (m, t) in hashes and h != hashes[(m, t)]
            for m, t, h in zip(df["method"], df["task"], df["prediction_hash"])
        ],
        index=df.index,
        dtype=bool,
    )
    if stale.any():
        log(
            f"{int(stale.sum())} row(s) were computed by other code or settings: those of this "
            f"grid are computed again, and each is moved to {STALE} before the first new row"
        )
    for scene in set(df["scene"]) & {Path(d).name for d in cfg.datasets}:
        folder = cfg.dataset(scene)
        changed = ~stale & (df["scene"] == scene) & (df["render_key"] != source_key(folder))
        if changed.any():
            log(
                f"the contents of {folder} changed since {int(changed.sum())} row(s) were "
                "computed; computing them again"
            )
        stale |= changed
    for scene in set(df["scene"]) & set(cfg.scenes) - {Path(d).name for d in cfg.datasets}:
        rows = ~stale & (df["scene"] == scene)
        tasked = rows & df["task"].isin(TASK_RUNNERS)  # a row of each task against its own rig
        names = {
            (sd, t): entry_names(scene, int(sd), cfg.render(t), ws.renders)
            for sd, t in set(zip(df["seed"][tasked], df["task"][tasked]))
        }
        found = [
            k in names.get(st, ()) for k, st in zip(df["render_key"], zip(df["seed"], df["task"]))
        ]
        changed = tasked & ~pd.Series(found, index=df.index, dtype=bool)
        if changed.any():
            log(
                f"the scene {scene} (its generator, parameters or render settings) changed "
                f"since {int(changed.sum())} row(s) were computed; computing them again"
            )
        stale |= changed
    unnamed = ~stale & (pixels_of(df) == NO_PIXELS)
    if unnamed.any():
        log(
            f"{int(unnamed.sum())} row(s) name no pixels (written before rows recorded the "
            "images they read), so nothing shows which renders they read; computing them again"
        )
    stale |= unnamed
    _check_known_pixels(cfg, ws, df[~stale])
    errored = ~stale & df["failure"].str.startswith(ERROR)
    if errored.any():
        log(f"{int(errored.sum())} row(s) could not be computed last time; computing them again")
    df = df[~(stale | errored)]
    rescore = altered[~(stale | errored)] | df["method"].isin(known) & (
        options.reevaluate | (df["evaluation_hash"] != evaluation_hash())
    )
    return df, rescore


def _refuse_other_pixels(rows: pd.DataFrame, scene: str, seed: int, pixels: str, ws) -> None:
    """One line when `rows` of (scene, seed) read other pixels than its entry here has."""
    other = rows[(rows["scene"] == scene) & (rows["seed"] == seed) & (pixels_of(rows) != pixels)]
    if len(other):
        raise BenchError(
            f"{ws.runs_csv}: {len(other)} row(s) of {scene} seed {seed} read pixels "
            f"{other['pixels'].iloc[0]}, and its entry here has {pixels} (renders differ "
            "between machines; the reference renders do not): run into a new --results "
            "folder, or with --overwrite"
        )


def _check_known_pixels(cfg: BenchConfig, ws: Workspace, rows: pd.DataFrame) -> None:
    """Refuse rows of a rendered scene that read other pixels than its entry here, where
    they are known before rendering (`bench.render.entry.known_pixels`; `_rendered`'s
    entries are checked as they are made)."""
    datasets = {Path(d).name for d in cfg.datasets}
    for scene, seed, task in set(zip(rows["scene"], rows["seed"], rows["task"])):
        if scene in datasets or task not in TASK_RUNNERS or scene not in cfg.scenes:
            continue
        px = known_pixels(scene, int(seed), cfg.render(task), ws.renders)
        if px is not None:
            _refuse_other_pixels(rows[rows["task"] == task], scene, seed, px, ws)


def _keys(frame: pd.DataFrame) -> set[tuple]:
    """The rows' keys (`KEY`), as a unit's job is keyed (`_job_key`)."""
    return set(zip(*(frame[k] for k in KEY)))


def _job_key(unit: Unit, job: Job) -> tuple:
    return (*astuple(unit), *job)


def _missing(cfg: BenchConfig, df: pd.DataFrame, rescore: pd.Series) -> tuple[set, dict]:
    """The keys of the current rows, and the work of each unit with rows missing (or only
    to score again); one line where the grid has no unit at all. The rows of other bags
    (another --bag-size or --bags) are other rows, kept."""
    done, again = _keys(df[~rescore]), _keys(df[rescore])
    work = {}
    for unit in cfg.units():
        missing = [j for j in cfg.jobs(unit.method) if _job_key(unit, j) not in done]
        if missing:
            redo = all(_job_key(unit, j) in again for j in missing)
            work[unit] = Work(tuple(missing), rescore=redo)
    if not cfg.units():
        only = [
            f"the {', '.join(r.kinds)} methods only {t}" for t, r in TASK_RUNNERS.items() if r.kinds
        ]
        raise BenchError(
            f"nothing to compute: no method of {', '.join(cfg.methods)} runs a task of "
            f"{', '.join(cfg.tasks)} (the COLMAP peers run only "
            f"{', '.join(t for t, r in TASK_RUNNERS.items() if r.spec.peers)}"
            + "".join(f"; {o}" for o in only)
            + ")"
        )
    return done, work


def _run_in(
    cfg: BenchConfig, ws: Workspace, options: RunOptions, report: Report | None
) -> pd.DataFrame:
    t_start = time.perf_counter()
    invocation = {
        "id": time.strftime("%Y%m%dT%H%M%S") + f"-{os.getpid()}-{next(_INVOCATIONS)}",
        "git_commit": git_commit(),  # before this run rewrites any tracked result file
    }
    check_results_dir(ws.results, cfg.run.as_dict(), options.overwrite, RunConfig().as_dict())
    for line in cfg.placed[1]:
        log(line)
    code_hash(PREDICTION_CODE), evaluation_hash()  # taken once, from the code that starts
    df, rescore = _current_rows(cfg, ws, options)
    done, work = _missing(cfg, df, rescore)
    n_rows = sum(len(w.jobs) for w in work.values())
    stage_s = dict.fromkeys(
        ["render", "frontend", "select", "match", "verify", "task", "evaluate_matches", "evaluate"],
        0.0,
    )
    n_again = sum(len(w.jobs) for w in work.values() if w.rescore)
    todo = [f"{n_rows - n_again} to compute"] if n_rows > n_again or not n_rows else []
    todo += [f"{n_again} rows to score again from their stored predictions"] if n_again else []
    log(f"{len(done)} of {len(done) + n_rows} rows already in {ws.runs_csv}; " + ", ".join(todo))
    groups = sorted({u.group for u in work}, key=lambda g: (cfg.scenes.index(g[0]), g[1]))
    wall = {"render": time.perf_counter()}
    entries = _rendered(cfg, ws, groups, options.cluster, stage_s)
    same_rig = df[df["task"].map(lambda t: cfg.render(t) == cfg.render()).astype(bool)]
    for (scene, seed), entry in entries.items():
        if not cfg.dataset(scene):
            _refuse_other_pixels(same_rig, scene, seed, pixels_key(entry), ws)
    wall["render"] = time.perf_counter() - wall["render"]
    plan = Plan(entries, work)
    t_runs = time.perf_counter()
    try:
        _append_rows(plan, cfg, ws, options, stage_s, done, invocation["id"])
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the rows written keep their seconds
        stage_s["runs_wall"] = wall["runs"] = time.perf_counter() - t_runs
        seconds = {"total": time.perf_counter() - t_start}
        _interrupted(ws, cfg, invocation | {"seconds": seconds, "wall": wall}, stage_s)
        raise
    stage_s["runs_wall"] = wall["runs"] = time.perf_counter() - t_runs
    out = read_runs(ws.runs_csv)
    invocation |= {
        "rows": n_rows,
        "seconds": {"total": time.perf_counter() - t_start, **stage_s},
        "wall": wall | {"total": time.perf_counter() - t_start},
        "cluster": _cluster_record(options.cluster),
    }
    _reported(cfg, ws, invocation, out, report, t_start)
    ours = in_grid(cfg, out)
    said = [
        failures(ours),
        outcomes(ours),
        exclusions(ours, Vocabulary.current(), bool(cfg.datasets)),
    ]
    said = [s for s in said if s]
    log(
        f"{n_rows} rows done, {len(done)} reused, in {invocation['seconds']['total']:.0f} s"
        + (f"; of the grid's {len(ours)} rows, " + "; ".join(said) if said else "")
        + f"; results in {ws.results}"
    )
    return out


def _reported(cfg, ws: Workspace, invocation: dict, out, report: Report | None, t_start) -> None:
    """The run's manifest, written before its report (whose page shows it) and again with
    the report's seconds."""
    write_manifest(ws, cfg.run.as_dict(), invocation, out)
    if report is not None:
        t = time.perf_counter()
        report(of_bags(cfg, out), ws.results, ws.renders)
        invocation["seconds"]["report"] = invocation["wall"]["report"] = time.perf_counter() - t
        invocation["seconds"]["total"] = time.perf_counter() - t_start
        invocation["wall"]["total"] = invocation["seconds"]["total"]
        write_manifest(ws, cfg.run.as_dict(), invocation, out)


def _append_rows(plan, cfg: BenchConfig, ws: Workspace, options: RunOptions, stage_s, done, run_id):
    """Compute the plan's units, appending each one's rows to `runs.csv` as it finishes;
    the folder is bound by the first rows it gets, when the rows this run replaces are
    moved aside (`keep_runs`)."""
    with models_replaced(ws.results, options.overwrite) as state:
        for new in _computed(plan, cfg.run, ws, options.cluster, stage_s):
            vocab = Vocabulary.current()
            if not state["bound"]:
                bind_results_dir(ws.results, cfg.run.as_dict(), vocab, options.overwrite)
                moved = keep_runs(ws.runs_csv, done)  # the rows computed again go first
                if moved:
                    log(
                        f"{moved} row(s) of {ws.runs_csv} that this run replaces or no "
                        f"longer counts as current moved, as they were, to {STALE}"
                    )
                state["bound"] = True
            rows = [r | {"invocation": run_id} for r in new]
            check_unchanged()  # the rows' hashes name the code that computed them
            append_runs(ws.runs_csv, rows, vocab)


def _interrupted(ws: Workspace, cfg: BenchConfig, invocation: dict, stage_s: dict) -> None:
    """The manifest of an interrupted run: its invocation kept with the rows it wrote and
    the seconds it spent (`interrupted`), so that a resume adds to them (docs/results.md)."""
    if not ws.runs_csv.is_file():
        return
    try:
        rows = read_runs(ws.runs_csv)
    except BenchError:  # nothing more to keep than the rows themselves
        return
    n = int((rows["invocation"] == invocation["id"]).sum())
    invocation["seconds"] |= stage_s
    write_manifest(ws, cfg.run.as_dict(), invocation | {"rows": n, "interrupted": True}, rows)


def _rendered(
    cfg: BenchConfig, ws: Workspace, groups: list, cluster: Cluster, stage_s: dict
) -> dict[tuple[str, int], Path]:
    """The render entry (or dataset folder) of each (scene, seed), in `groups`' order: the
    scenes whose entry is missing or damaged rendered side by side, one process per worker
    of a local cluster (`bench.render.entry.render_scenes`); their seconds summed into
    `stage_s["render"]`. A whole entry (every file's checksum verified) is taken here."""
    t = time.perf_counter()
    entries = {g: cfg.dataset(g[0]) for g in groups if cfg.dataset(g[0])}
    for g in groups:
        entry = cached_entry(*g, cfg.render(), ws.renders) if g not in entries else None
        if entry is not None:
            entries[g] = entry
    stage_s["render"] += time.perf_counter() - t
    scenes = [g for g in groups if g not in entries]
    side_by_side = cluster.workers if cluster.scheduler is None else 1
    render = partial(render_scene, cfg=cfg.render(), renders_dir=ws.renders)
    with progress("render", len(groups), "scene", shown=bool(scenes), initial=len(entries)) as bar:
        for (sc, sd), entry, seconds in render_scenes(scenes, render, side_by_side):
            entries[sc, sd] = entry
            stage_s["render"] += seconds
            bar.set_postfix_str(f"{sc} seed {sd}")
            bar.update()
    return {g: entries[g] for g in groups}


def _cluster_record(cluster: Cluster) -> dict:
    """What ran the units: the workers (a local cluster's; 1: this process) or the
    scheduler's address, and this machine's cores."""
    workers = cluster.workers if cluster.scheduler is None else cluster.scheduler
    return {"workers": workers, "cores": os.cpu_count()}


def in_grid(cfg: BenchConfig, rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of `cfg`'s grid (a results folder may hold more)."""
    units = {astuple(u) for u in cfg.units()}
    keep = [
        (sc, sd, p, b, bag) in units and t in cfg.tasks and pr in cfg.protocols_of(t)
        for sc, sd, p, b, bag, t, pr in rows[list(KEY)].itertuples(index=False)
    ]
    return rows[keep]


def of_bags(cfg: BenchConfig, rows: pd.DataFrame) -> pd.DataFrame:
    """The rows a page of `cfg`'s invocation reads: every row but those of its datasets'
    other bags (another --bag-size or --bags, kept in the folder beside them)."""
    asked = {(u.scene, u.bag) for u in cfg.units()}
    scenes = {Path(d).name for d in cfg.datasets}
    keep = [sc not in scenes or (sc, bag) in asked for sc, bag in zip(rows["scene"], rows[BAG])]
    return rows[keep]


def _computed(plan: Plan, cfg: RunConfig, ws: Workspace, cluster: Cluster, stage_s: dict):
    """The rows of each unit as it finishes, with progress bars; the stage seconds added
    to `stage_s`."""
    rows = sum(len(w.jobs) for w in plan.work.values())
    bagged = {u.group for u in plan.work if u.bag}
    with (
        progress("frontend", len(plan.entries), "scene") as fbar,
        progress("runs", rows, "rows") as bar,
    ):

        def scene_ready(group, info):
            scene, seed = group
            stage_s["frontend"] += info["seconds"]
            fbar.set_postfix_str(f"{scene} {'bag' if group in bagged else 'seed'} {seed}")
            fbar.update()
            if bar.n == 0:  # the time left counts from the first front end, not before it
                bar.reset(total=rows)

        for new in execute(plan, cfg, ws, cluster, scene_ready):
            _add_seconds(stage_s, new)
            yield new
            first = new[0]
            bar.set_postfix_str(
                f"{first['scene']} s{first['seed']} {first['method']} b{first['budget']}"
            )
            bar.update(len(new))


def _add_seconds(stage_s: dict[str, float], new: list[dict]) -> None:
    """A unit's stage seconds into the run's totals (the shared stages counted once)."""
    for k in ("frontend", "select", "match", "verify", "evaluate_matches"):
        stage_s[k] += np.nan_to_num(new[0].get(f"{k}_ms", 0.0)) / 1000
    for r in new:
        stage_s["task"] += np.nan_to_num(r.get("task_ms", 0.0)) / 1000
        stage_s["evaluate"] += np.nan_to_num(r.get("evaluate_ms", 0.0)) / 1000
