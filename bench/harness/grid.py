"""`bench run`: every (scene, seed, policy, budget) of the grid, resumable and reproducible.

Stages per (scene, seed): render (cached) -> front end (cached) -> for each policy and
budget: one run (`bench.harness.pipeline.run_one`), its row appended to `runs.csv` at once (the
file is rewritten through a temporary name, so an interrupt keeps every finished row).
The configuration is stored in `config.json` beside the results; a run into a directory
holding another configuration is refused unless `overwrite`.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from dataclasses import asdict, dataclass, field
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pandas as pd

from bench import ROOT, BenchError
from bench.backend.peers import PEERS
from bench.backend.reconstruction import PROTOCOLS, check_protocols
from bench.console import log, progress
from bench.files import exclusive, write_text_atomic
from bench.frontend import feedback
from bench.frontend.policies import POLICIES, check_policies, learned_weights
from bench.frontend.views import source_key
from bench.harness import plugins
from bench.harness.execute import check_scheduler, execute
from bench.harness.pipeline import ORACLE, TASKS, RunConfig, row_hash
from bench.harness.report import write_report
from bench.harness.runs import (
    DAMAGED,
    bind_results_dir,
    check_results_dir,
    read_runs,
    set_aside_damaged,
)
from bench.harness.tables import KEY
from bench.render.entry import render_scene
from bench.scenes.spec import load_spec, scene_names

DEFAULT_POLICIES = (
    "random",
    "texture",
    "grid",
    "adaptive",
    "response",
    "ssc",
    "quadtree",
    "adaptive-fast",
    feedback.NAME,
    "learned",
    "cross-view",
    "all",
    ORACLE,
    *PEERS,
)


@dataclass(frozen=True)
class BenchConfig:
    """The benchmark grid and the configuration of every run in it."""

    scenes: tuple[str, ...] = field(default_factory=lambda: tuple(scene_names()))
    seeds: tuple[int, ...] = (0, 1, 2)
    policies: tuple[str, ...] = DEFAULT_POLICIES
    budgets: tuple[int, ...] = (128, 256, 512)
    tasks: tuple[str, ...] = TASKS
    protocols: tuple[str, ...] = tuple(PROTOCOLS)
    run: RunConfig = field(default_factory=RunConfig)
    dataset: str | None = None
    """A dataset folder (`bench run --dataset`) instead of rendered scenes: its one scene
    is the folder's name, with seed 0."""

    def validate(self) -> BenchConfig:
        if self.dataset is None:
            for s in self.scenes:
                load_spec(s)
        plugins.load(self.run.policy.modules)
        check_policies(self.policies, extra=(feedback.NAME, ORACLE, *PEERS))
        if "learned" in self.policies and self.dataset is None:
            trained = set(learned_weights(self.run.policy.learned_weights)["seeds"])
            shared = sorted(trained & set(self.seeds))
            if shared:
                raise BenchError(
                    f"the learned weights were trained on seed(s) {shared}, which are also "
                    "evaluation seeds; evaluate on other seeds, or train on others "
                    "(bench train-weights --seeds ...)"
                )
        check_protocols(self.protocols)
        unknown = [t for t in self.tasks if t not in TASKS]
        if unknown or not self.tasks:
            raise BenchError(
                f"unknown task {unknown[0] if unknown else ''!r}; valid: {', '.join(TASKS)}"
            )
        if not self.seeds or min(self.seeds) < 0:
            raise BenchError(f"seeds must be non-negative integers, got {list(self.seeds)}")
        if not self.budgets or min(self.budgets) <= 0:
            raise BenchError(f"budget must be positive integers, got {list(self.budgets)}")
        if self.dataset is None:
            self.run.render.validate()
        self.run.detector.validate()
        self.run.policy.validate()
        return self

    def as_dict(self) -> dict:
        return json.loads(json.dumps(asdict(self)))  # tuples as lists, as stored

    def units(self) -> list[tuple[str, int, str, int]]:
        """Every (scene, seed, policy, budget) of the grid that has a job; `all` and `colmap`
        are one unit per scene and seed, with budget 0 (the whole pool; COLMAP's default)."""
        return [
            (sc, sd, p, b)
            for sc in self.scenes
            for sd in self.seeds
            for p in self.policies
            for b in ((0,) if p in ("all", "colmap") else self.budgets)
            if self.jobs(p)
        ]

    def jobs(self, policy: str) -> list[tuple[str, str]]:
        """Every (task, protocol) of a unit of `policy` (the peers run the sfm task only)."""
        tasks = [t for t in self.tasks if t == "sfm" or policy not in PEERS]
        return [(t, pr) for t in tasks for pr in self.protocols]


def run_benchmark(
    cfg: BenchConfig,
    results: Path,
    renders: Path,
    overwrite: bool = False,
    set_aside: bool = False,
    workers: int = 1,
    scheduler: str | None = None,
) -> pd.DataFrame:
    """Run whatever of the grid is missing from `results/runs.csv`, then write the report
    (see `bench.harness.runs` for what counts as finished, damaged or refused). One run at
    a time holds a results folder; another is refused in one line while it does."""
    cfg.validate()
    if scheduler is not None:
        check_scheduler(scheduler)
    results, renders = Path(results), Path(renders)
    created = not results.exists()
    try:
        results.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(f"cannot write to {results}: {e.strerror}") from e
    try:
        with exclusive(results / ".bench-run.lock", f"results folder {results}"):
            return _run_in(cfg, results, renders, overwrite, set_aside, workers, scheduler)
    finally:
        if created and results.is_dir() and not any(results.iterdir()):
            results.rmdir()  # a refused run leaves no folder behind


def _run_in(cfg, results, renders, overwrite, set_aside, workers, scheduler) -> pd.DataFrame:
    t_start = time.perf_counter()
    invocation = {
        "id": time.strftime("%Y%m%dT%H%M%S") + f"-{os.getpid()}",
        "git_commit": _git_commit(),  # before this run rewrites any tracked result file
    }
    check_results_dir(results, cfg.run.as_dict(), overwrite)
    runs_csv = results / "runs.csv"
    if set_aside and runs_csv.exists() and not overwrite:
        log(f"{set_aside_damaged(runs_csv)} damaged row(s) of {runs_csv} set aside in {DAMAGED}")
    df = (
        read_runs(runs_csv)
        if runs_csv.exists() and not overwrite
        else pd.DataFrame(columns=[*KEY, "config_hash", "render_key"])
    )
    # each row against its policy's hash; a policy not registered now (a module not given
    # this time) keeps its rows as they are
    known = set(POLICIES) | {feedback.NAME, ORACLE, *PEERS}
    expected = df["policy"].map({p: row_hash(cfg.run, p) for p in set(df["policy"]) & known})
    stale = expected.notna() & (df["config_hash"] != expected)
    if stale.any():
        log(f"{int(stale.sum())} row(s) were computed by other code; computing them again")
    if cfg.dataset is not None:
        changed = ~stale & (df["render_key"] != source_key(Path(cfg.dataset)))
        if changed.any():
            log(
                f"the contents of {cfg.dataset} changed since {int(changed.sum())} row(s) were "
                "computed; computing them again"
            )
        stale |= changed
    df = df[~stale]
    done = set(map(tuple, df[list(KEY)].itertuples(index=False)))
    rows = df.to_dict("records")
    todo = {}
    for unit in cfg.units():
        missing = [j for j in cfg.jobs(unit[2]) if (*unit, *j) not in done]
        if missing:
            todo[unit] = missing
    n_rows = sum(len(j) for j in todo.values())
    if not cfg.units():
        raise BenchError(
            f"nothing to compute: no policy of {', '.join(cfg.policies)} runs a task of "
            f"{', '.join(cfg.tasks)} (the COLMAP peers run the sfm task only)"
        )
    stage_s = dict.fromkeys(
        ["render", "frontend", "select", "match", "verify", "task", "evaluate_matches", "evaluate"],
        0.0,
    )
    log(f"{len(done)} of {len(done) + n_rows} rows already in {runs_csv}; {n_rows} to do")

    pending = sorted({u[:2] for u in todo}, key=lambda g: (cfg.scenes.index(g[0]), g[1]))
    entries = {}
    with progress("render", len(pending)) as bar:
        for sc, sd in pending:
            t = time.perf_counter()
            entries[sc, sd] = (
                Path(cfg.dataset)
                if cfg.dataset is not None
                else render_scene(sc, sd, cfg.run.render, renders)
            )
            stage_s["render"] += time.perf_counter() - t
            bar.set_postfix_str(f"{sc} seed {sd}")
            bar.update()
    t_runs, bound = time.perf_counter(), False
    with progress("frontend", len(pending)) as fbar, progress("runs", len(todo)) as bar:

        def scene_ready(group, info):
            stage_s["frontend"] += info["seconds"]
            fbar.set_postfix_str(f"{group[0]} seed {group[1]}")
            fbar.update()

        for new in execute(
            entries, todo, cfg.run, cfg.budgets, results, renders, workers, scheduler, scene_ready
        ):
            if not bound:  # the folder is bound by the first rows it gets, not before
                bind_results_dir(results, cfg.run.as_dict(), overwrite)
                bound = True
            for k in ("select", "match", "verify", "evaluate_matches"):
                stage_s[k] += np.nan_to_num(new[0].get(f"{k}_ms", 0.0)) / 1000
            for r in new:
                stage_s["task"] += np.nan_to_num(r.get("task_ms", 0.0)) / 1000
                stage_s["evaluate"] += np.nan_to_num(r.get("evaluate_ms", 0.0)) / 1000
            rows += [r | {"invocation": invocation["id"]} for r in new]
            table = pd.DataFrame(rows).sort_values(list(KEY), kind="stable")
            write_text_atomic(runs_csv, table.to_csv(index=False))
            r = new[0]
            bar.set_postfix_str(f"{r['scene']} s{r['seed']} {r['policy']} b{r['budget']}")
            bar.update()
    stage_s["runs_wall"] = time.perf_counter() - t_runs
    t = time.perf_counter()
    out = read_runs(runs_csv)
    write_report(out, results, renders)
    stage_s["report"] = time.perf_counter() - t
    invocation |= {"rows": n_rows, "seconds": {"total": time.perf_counter() - t_start, **stage_s}}
    write_manifest(results, cfg, invocation, out, renders)
    log(
        f"{n_rows} rows done, {len(done)} reused, in {invocation['seconds']['total']:.0f} s; results in {results}"
    )
    return out


def _git_commit() -> str:
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "") if sha else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def write_manifest(
    results: Path, cfg: BenchConfig, invocation: dict, rows: pd.DataFrame, renders: Path
) -> None:
    """Versions, variant, host, settings and the invocations that computed the rows of
    `runs.csv`: each with its commit and seconds per stage, kept while it owns a row (a rerun
    that computes nothing adds nothing), and their sum."""
    path = results / "manifest.json"
    try:
        earlier = json.loads(path.read_text()).get("invocations", [])
    except (OSError, ValueError, AttributeError):
        earlier = []
    live = set(rows["invocation"])
    kept = [i for i in earlier if isinstance(i, dict) and i.get("id") in live]
    if invocation["rows"]:
        kept.append(invocation)
    for inv in kept:
        inv["rows_now"] = int((rows["invocation"] == inv["id"]).sum())
    total: dict[str, float] = {}
    for inv in kept:
        for k, v in inv["seconds"].items():
            total[k] = total.get(k, 0.0) + v
    entries = [renders / k for k in rows["render_key"].unique()]
    metas = [
        json.loads((e / "meta.json").read_text()) for e in entries if (e / "meta.json").is_file()
    ]
    packages = [
        "mitsuba",
        "drjit",
        "numpy",
        "opencv-contrib-python-headless",
        "pycolmap",
        "pandas",
        "matplotlib",
        "scipy",
    ]
    manifest = {
        "versions": {"python": platform.python_version(), **{p: version(p) for p in packages}},
        "variant": sorted({m["variant"] for m in metas}),
        "host": {"node": platform.node(), "platform": platform.platform(), "cpus": os.cpu_count()},
        "settings": cfg.run.as_dict(),
        "config_hash": cfg.run.hash,
        "grid": {k: sorted(map(str, rows[k].unique())) for k in KEY},
        "git_commit": sorted({inv["git_commit"] for inv in kept}),
        "invocations": kept,
        "seconds": total,
        "render_entries": sorted(e.name for e in entries),
    }
    write_text_atomic(path, json.dumps(manifest, indent=1))
