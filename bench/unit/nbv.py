"""The next-views task (`nbv`): active acquisition, where a view chooser recommends the
camera poses to capture next (the paper's section 7), measured exactly on rendered scenes
(any pose of the planned path can be rendered with its ground truth) and on datasets.

A unit (scene, seed, chooser, budget) starts from an initial capture and a set of
candidate poses (`RunConfig.nbv`): on a rendered scene, `initial` views evenly on its path
(6: the sparse regime's rig) and the `between` path positions between consecutive ones
(3: the rest of the dense regime's 21-view path; each view rendered once, cached by its
path position); on a dataset, every `every`-th image of its model (name order) and the
others with their model poses. The chooser (`bench.acquisition.choosers`, or the oracle,
`bench.evaluation.next_views`) picks a candidate, the view joins the capture (its image is
read only now), and so on until the most views of `added` are added. Each job (a track
protocol) has its own sequence: the chooser's reconstruction follows the protocol.

A capture (a set of path views, in path order) is run as the other tasks run a scene, on
its views alone, at the unit's budget with the keypoint policy `nbv.policy`:

* with the rig's poses: the front end of the captured views (each view's pool detected once
  per path, its signals computed over the captured views only: a candidate's image never
  enters), the policy's selection, matching and COLMAP verification, and the tri task's
  known-pose triangulation (`TASK_RUNNERS["tri"]`) under the job's protocol. This is what a
  chooser sees (`ChooserInput`) and the capture's tri score;
* without them (the sfm task's pose-free front end and selection): matching and the sfm
  task's mapping: the capture's sfm score.

Scores of a capture (`capture_scores`): `completeness_k<k>`, the tri task's
acc_completeness_pct (points within 0.10 of the surface) against the reconstructable points
of the whole path (tracks of the path's candidate pools over all its views spanning as many
views as the protocol asks), so every capture of a scene and seed counts against the same
number and a score is comparable across k and choosers; NaN without per-pixel truth.
`maa_k<k>`: the sfm task's pose mAA over the pairs of captured views against the rig's (a
dataset model's) poses. After k added views the gains are `completeness_gain_k<k>` and
`maa_gain_k<k>` (the score minus the initial capture's); `candidates` is how many were
offered. The oracle picks by the completeness where there is per-pixel truth, else by mAA.

Each capture's front end, selection and matches are computed once per process and reused
by every unit of the scene and seed that reaches it (the initial capture is every unit's);
a row's seconds (`frontend_ms`, `select_ms`, `match_ms`, `verify_ms`, `task_ms`,
`choose_ms`) are those its unit spent. Stored per job in the unit's folder
(`Workspace.model_dir`, `nbv/` and `nbv/twoview/`): each scored capture's tri model in
`k<k>/` and sfm model in `k<k>/sfm/`, and in `prediction.json` the views chosen and the
captures scored, so rows are scored again (`--reevaluate`) from the stored models alone.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from bench import BenchError, MethodFailed
from bench.acquisition.choosers import (
    CHOOSER,
    CandidatePose,
    CapturedView,
    ChooserInput,
    OwnModel,
    choose,
    chooser_rng,
)
from bench.evaluation.next_views import VIEW_ORACLE, best_candidate
from bench.frontend.colmap_model import read_reconstruction
from bench.frontend.geometry import IMAGES, RIG
from bench.frontend.signals import compute_signals
from bench.frontend.views import Source
from bench.results import Workspace
from bench.unit import select_match
from bench.unit.config import MAX_ADDED, RunConfig
from bench.unit.evaluate import identities, make_row, render_seconds
from bench.unit.predict import Keys, LoadedScene, clear_model, export_model, read_record
from bench.unit.tasks import TASK_RUNNERS, Matched, TaskRunner, register
from bench.vocabulary import (
    AT_LEAST_0,
    FRACTION,
    METHODS,
    NEXT_VIEWS,
    PROTOCOLS,
    Job,
    Metric,
    Task,
    Unit,
    declare_metric,
)

SCORED = {RIG: "tri", IMAGES: "sfm"}
"""The task whose reconstruction scores a capture under each geometry."""
STAGES = ("frontend", "select", "match", "verify", "task", "choose")
"""The stages whose seconds an nbv row holds (`<stage>_ms`)."""


def _k_metrics(k: int) -> list[Metric]:
    views = f"{k} view{'s' * (k != 1)} added"
    out = [
        Metric(f"completeness_k{k}", AT_LEAST_0, title=f"Tri acc. completeness %, {views}"),
        Metric(f"maa_k{k}", FRACTION, title=f"SfM pose mAA, {views}"),
    ]
    if k:
        out += [
            Metric(
                f"completeness_gain_k{k}",
                (-math.inf, None),
                title=f"Tri completeness gain (points), {views}",
                failure=0.0,
            ),
            Metric(f"maa_gain_k{k}", (-1.0, 1.0), title=f"SfM mAA gain, {views}", failure=0.0),
        ]
    return out


for _k in range(MAX_ADDED + 1):
    for _metric in _k_metrics(_k):
        declare_metric(_metric)
declare_metric(Metric("candidates", doc="the candidate poses an nbv unit was offered"))
declare_metric(Metric("initial_views", doc="the views of an nbv unit's initial capture"))

GAINS = tuple(
    f"{s}_gain_k{k}"
    for k in (2, 1, 4, 3, *range(5, MAX_ADDED + 1))
    for s in ("maa", "completeness")
)
SCORES = tuple(f"{s}_k{k}" for s in ("maa", "completeness") for k in range(MAX_ADDED + 1))


def capture_plan(names: list[str], cfg: RunConfig, dataset: bool) -> tuple[list[int], list[int]]:
    """(the initial capture, the candidates) as positions on the path (module docstring)."""
    step = cfg.nbv.every if dataset else cfg.nbv.between + 1
    initial = list(range(0, len(names), step))
    return initial, [v for v in range(len(names)) if v not in initial]


@dataclass
class Context:
    """What a unit's captures are computed with, and the seconds it spent per stage."""

    scene: LoadedScene
    unit: Unit
    cfg: RunConfig
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def settings(self) -> str:
        return repr(self.cfg)

    def spent(self, stage: str, since: float) -> None:
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - since

    @property
    def names(self) -> list[str]:
        return [v.name for v in self.scene.fronts[RIG].views]


_CACHE: dict = {}
"""What this process computed of one scene and seed's captures (module docstring)."""


def _cached(ctx: Context, key: tuple, compute: Callable):
    """`compute()`, once per process for the scene, settings and `key`."""
    if _CACHE.get("scene") is not ctx.scene or _CACHE.get("settings") != ctx.settings:
        _CACHE.clear()
        _CACHE.update(scene=ctx.scene, settings=ctx.settings)  # held: its id is not reused
    if key not in _CACHE:
        _CACHE[key] = compute()
    return _CACHE[key]


def _front(ctx: Context, views: tuple, grant: str):
    """The captured views under a geometry, their pools and signals (computed over them)."""

    def compute():
        t = time.perf_counter()
        path, cfg = ctx.scene.fronts[RIG], ctx.cfg
        vs = [path.views[v] if grant == RIG else path.views[v].without_pose() for v in views]
        work = [v.scale_to(cfg.detector.max_image_size) for v in vs]
        pools = [path.pools[v].scaled(sx, sy) for v, (_, sx, sy) in zip(views, work)]
        reads = METHODS[cfg.nbv.policy].reads
        sigs, _ = compute_signals([w for w, _, _ in work], pools, cfg.detector, cfg.signals, reads)
        ctx.spent("frontend", t)
        return vs, [path.pools[v] for v in views], sigs

    return _cached(ctx, ("front", views, grant), compute)


def _state(ctx: Context, views: tuple, grant: str):
    """A capture's views, pools, signals, selections and verified pairs under a geometry,
    at the unit's budget."""

    def compute():
        vs, pools, sigs = _front(ctx, views, grant)
        cams, cfg, policy = [v.camera for v in vs], ctx.cfg, ctx.cfg.nbv.policy
        t = time.perf_counter()
        sel, _, _ = select_match.select(vs, pools, sigs, replace(ctx.unit, method=policy), cfg)
        ctx.spent("select", t)
        pairs, seconds = select_match.match(cams, pools, sel, policy, cfg)
        for stage, s in seconds.items():
            ctx.seconds[stage] = ctx.seconds.get(stage, 0.0) + s
        return vs, pools, sigs, sel, pairs

    return _cached(ctx, ("state", views, grant, ctx.unit.budget), compute)


def _matched(ctx: Context, views: tuple, grant: str) -> Matched:
    vs, pools, _, sel, pairs = _state(ctx, views, grant)
    xy = [c.xy[s] for c, s in zip(pools, sel)]
    return Matched([v.camera for v in vs], [v.name for v in vs], xy, pairs)


def reconstruction(ctx: Context, views: tuple, grant: str, protocol: str):
    """A capture's model under a geometry (the tri task's with the poses, the sfm task's
    without), at the unit's budget under `protocol`: (model or None, failure)."""

    def compute():
        m = _matched(ctx, views, grant)
        runner = TASK_RUNNERS[SCORED[grant]]
        t = time.perf_counter()
        rec = runner.reconstruct(m, ctx.cfg.backend, protocol)
        ctx.spent("task", t)
        model = rec.model if rec.model is not None or runner.record is None else runner.record(m)
        return model, rec.failure

    key = ("model", views, grant, ctx.unit.budget, protocol)
    return _cached(ctx, key, compute)


def capture_scores(scene: LoadedScene, names: list[str], models: dict, protocol: str) -> dict:
    """{'completeness': the tri score, 'maa': the sfm score} of a capture (its view
    names; `models`: its tri and sfm models by geometry, None where there is none)."""
    truth = scene.truth
    path = [v.name for v in scene.fronts[RIG].views]
    cams = [truth.cams[path.index(n)] for n in names]
    tri = TASK_RUNNERS[SCORED[RIG]].evaluate(truth, models[RIG], names, protocol, {})
    sfm = TASK_RUNNERS[SCORED[IMAGES]].evaluate(
        replace(truth, cams=cams), models[IMAGES], names, protocol, {}
    )
    return {"completeness": tri["acc_completeness_pct"], "maa": sfm["maa"]}


def own_model(model) -> OwnModel:
    """A known-pose COLMAP model (image k + 1 is captured view k; a point's observation
    indexes the view's selection) as the chooser sees it."""
    pts = list(model.points3D.values()) if model is not None else []
    tracks = tuple(
        np.array([(el.image_id - 1, el.point2D_idx) for el in p.track.elements], int).reshape(-1, 2)
        for p in pts
    )
    return OwnModel(np.array([p.xyz for p in pts]).reshape(-1, 3), tracks)


Pick = Callable[[Context, tuple, list[int], int, str], int]
"""(unit context, the capture, the candidates left, views added so far, protocol) ->
the path position of the view to add."""


def chooser_pick(ctx: Context, views: tuple, left: list[int], step: int, protocol: str) -> int:
    """A chooser's pick, from what it may see (`ChooserInput`)."""
    vs, pools, sigs, sel, pairs = _state(ctx, views, RIG)
    model, _ = reconstruction(ctx, views, RIG, protocol)
    path = ctx.scene.fronts[RIG].views
    inp = ChooserInput(
        tuple(CapturedView(v, c, s, x) for v, c, s, x in zip(vs, pools, sigs, sel)),
        tuple(pairs),
        own_model(model),
        tuple(CandidatePose(c, path[c].camera) for c in left),
        PROTOCOLS[protocol],
    )
    t = time.perf_counter()
    pick = choose(ctx.unit.method, inp, chooser_rng(ctx.unit.seed, ctx.unit.method, step))
    ctx.spent("choose", t)
    return left[pick]


def oracle_pick(ctx: Context, views: tuple, left: list[int], step: int, protocol: str) -> int:
    """The oracle's pick: the candidate whose capture scores best against the ground truth
    (by completeness with per-pixel truth, else by mAA; `bench.evaluation.next_views`)."""
    grant = RIG if ctx.scene.truth.per_pixel else IMAGES
    score = "completeness" if grant == RIG else "maa"

    def value(c: int) -> float:
        capture = tuple(sorted((*views, c)))
        models = {
            g: reconstruction(ctx, capture, g, protocol)[0] if g == grant else None for g in SCORED
        }
        names = [ctx.names[v] for v in capture]
        return float(np.nan_to_num(capture_scores(ctx.scene, names, models, protocol)[score]))

    return best_candidate(left, value)


def _trajectory(ctx: Context, pick: Pick, protocol: str) -> tuple[list[int], list[int]]:
    """(the initial capture, the views added in order) of one job."""
    initial, offered = capture_plan(ctx.names, ctx.cfg, Source.kind(ctx.scene.entry) != "render")
    added = ctx.cfg.nbv.added
    if len(offered) < added[-1]:
        raise BenchError(
            f"{ctx.unit.scene} offers {len(offered)} candidate views, fewer than nbv.added's "
            f"{added[-1]}; lower nbv.added or nbv.every"
        )
    chosen: list[int] = []
    for step in range(added[-1]):
        left = [c for c in offered if c not in chosen]
        chosen.append(pick(ctx, tuple(sorted(initial + chosen)), left, step, protocol))
    return initial, chosen


def store_trajectory(pick: Pick) -> Callable:
    """The `Store` (`bench.unit.predict`) of a kind of method that picks views."""

    def store(scene, unit, jobs, cfg, ws, record) -> None:
        ctx = Context(scene, unit, cfg)
        record["names"] = ctx.names
        for job in jobs:
            ctx.seconds = dict.fromkeys(STAGES, 0.0)
            try:
                initial, chosen = _trajectory(ctx, pick, job.protocol)
            except MethodFailed as e:  # the chooser's rows fail (`bench.harness.execute`)
                e.tasks = (NEXT_VIEWS,)
                raise
            captures = {}
            for k in (0, *cfg.nbv.added):
                capture = tuple(sorted(initial + chosen[:k]))
                out = ws.model_dir(unit, job) / f"k{k}"
                for grant, folder in ((RIG, out), (IMAGES, out / "sfm")):
                    model, _ = reconstruction(ctx, capture, grant, job.protocol)
                    if model is not None:
                        export_model(model, folder)
                    else:
                        clear_model(folder)
                captures[k] = [ctx.names[v] for v in capture]
            record["jobs"][job.key] = {
                "grant": RIG,
                "failure": None,
                "seconds": dict(ctx.seconds),
                "initial": [ctx.names[v] for v in initial],
                "chosen": [ctx.names[v] for v in chosen],
                "captures": captures,
            }

    return store


def nbv_rows(
    scene: LoadedScene,
    unit: Unit,
    jobs: list[Job],
    cfg: RunConfig,
    ws: Workspace,
    read: None,
    keys: Keys,
) -> list[dict]:
    """The rows of a unit's jobs, scored from its stored models (module docstring)."""
    record, rows = read_record(ws.unit_dir(unit)), []
    for job, ident in zip(jobs, identities(scene.entry, unit, jobs, keys)):
        done = record["jobs"][job.key]
        t = time.perf_counter()
        got = {}
        for k, names in done["captures"].items():
            out = ws.model_dir(unit, job) / f"k{k}"
            models = {g: _read_model(f) for g, f in ((RIG, out), (IMAGES, out / "sfm"))}
            got[int(k)] = capture_scores(scene, names, models, job.protocol)
        scores = {f"{s}_k{k}": v for k, by in got.items() for s, v in by.items()}
        scores |= {
            f"{s}_gain_k{k}": v - got[0][s] for k, by in got.items() if k for s, v in by.items()
        }
        scores |= {
            "candidates": len(record["names"]) - len(done["initial"]),
            "initial_views": len(done["initial"]),
            "ground_truth": scene.truth.kind,
        }
        timing = done["seconds"] | {"evaluate": time.perf_counter() - t}
        rows.append(make_row(ident, scores, timing, done["failure"], render_seconds(scene.entry)))
    return rows


def _read_model(folder: Path):
    return read_reconstruction(folder) if (folder / "images.txt").is_file() else None


register(
    TaskRunner(
        Task(
            NEXT_VIEWS,
            RIG,
            needs=("maa_k0", "candidates"),
            metrics=(*GAINS, *SCORES, "candidates", "initial_views", "task_ms", "wall_ms"),
            doc="next views: a chooser adds views to an initial capture (off by default)",
            headline=GAINS[:2],
        ),
        kinds=(CHOOSER, VIEW_ORACLE),
        rig=lambda cfg: replace(cfg.render, views=cfg.nbv.path),
        default=False,
        settings=("nbv",),
    )
)
