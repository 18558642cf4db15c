"""The benchmark's vocabulary, in one place: the keys of a row, the track protocols, the
headline, the units of work, and the registries of methods and tasks.

A method (a selection policy, a reference or a stock-COLMAP peer) is declared where it is
implemented (`bench.frontend.policies.policy`, the feedback loop, the oracle, the peers),
with its display label, its role, the functions that implement it (`CODE`: its rows'
code hash starts there, `bench.harness.predict`) and its own settings (`SETTINGS`: a
dataclass, set as `--set <method>.<field>=value`); the display names, the baselines, the default grid
and the budget-0 rule are derived from these declarations. A task is declared where its
reconstruction and evaluation are (`bench.harness.tasks`). A results folder records the
vocabulary its rows were computed under (`vocabulary.json`), and the report reads that
record: it never imports the stages that compute.

This module imports nothing heavy, so every stage (and the report) may import it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

from bench import BenchError

KEY = ("scene", "seed", "method", "budget", "task", "protocol")
"""The columns that identify a row of `runs.csv`."""
UNIT_KEY = KEY[:4]
"""The columns that identify a unit of work (one selection, matched once per geometry)."""
PROTOCOLS = {"multiview": 3, "twoview": 2}
"""Track protocols: the fewest views a point's track may have (`bench.backend.reconstruction`)."""
HEADLINE = ("tri", "multiview")
"""The headline task and track protocol."""
HEADLINE_BUDGET = 256
HEADLINE_POLICY = "adaptive"
"""The paper's method, compared with every baseline in `table2.csv` and `paired.csv`."""
PAIRED_PEERS = ("colmap-b", "aliked-b", "disk-b")
"""The peers held to the same budget that `paired_sfm.csv` compares with, where they ran:
stock COLMAP's, and a learned detector's own top-B with LightGlue (on its pool)."""
REFERENCE_PEER = "colmap"
"""Stock COLMAP with all its features: a (scene, seed) it does not map in the sfm task
measures nothing, so it is marked (`REFERENCE_MAPS`) and left out of the sfm means."""
REFERENCE_MAPS = "reference_maps"
"""The `runs.csv` column saying whether `REFERENCE_PEER` maps the row's (scene, seed) in
the sfm task: 1 if it registers every view with pose mAA of at least `REFERENCE_MIN_MAA`,
0 if not (views registered with wrong poses are not a map), empty where it did not run."""
REFERENCE_MIN_MAA = 0.5
ORACLE = "oracle"
"""The ground-truth selection (`bench.evaluation.oracle`): a reference, never a policy."""
ROLES = ("baseline", "contender", "reference", "peer")
"""A baseline competes for "best baseline"; a contender is compared with the baselines; a
reference (`all`, the oracle) and a peer (stock COLMAP) are shown, never ranked as either."""
PERCENT, FRACTION, DEGREES, AT_LEAST_0 = (0.0, 100.0), (0.0, 1.0), (0.0, 180.0), (0.0, None)
RANGES: dict[str, tuple[float, float | None]] = {
    "views": AT_LEAST_0,
    "tentative_matches": AT_LEAST_0,
    "verified_matches": AT_LEAST_0,
    "inlier_pct": PERCENT,
    "match_precision_pct": PERCENT,
    "coverage_pct": PERCENT,
    "runtime_proxy": AT_LEAST_0,
    "runtime_scoring": AT_LEAST_0,
    "runtime_matching": AT_LEAST_0,
    "runtime_robust": AT_LEAST_0,
    "reconstructable": AT_LEAST_0,
    "points": AT_LEAST_0,
    "rmse": AT_LEAST_0,
    "median_error": AT_LEAST_0,
    **{f"accuracy_pct{t}": PERCENT for t in ("", "_0.02", "_0.05", "_0.20")},
    # accurate points per reconstructable point: above 100 where a model has more accurate
    # points than there are reconstructable ones (the sfm rows count them against the
    # multiview protocol's, two-view points included)
    **{f"acc_completeness_pct{t}": AT_LEAST_0 for t in ("", "_0.02", "_0.05", "_0.20")},
    "mean_track_length": AT_LEAST_0,
    "mean_tri_angle_deg": DEGREES,
    "render_s_per_view": AT_LEAST_0,
    "registered_views": AT_LEAST_0,
    "maa": FRACTION,
    "median_pose_err_deg": DEGREES,
    "cam_center_err": AT_LEAST_0,
    "mean_reproj_px": AT_LEAST_0,
    "keypoints_per_view": AT_LEAST_0,
}
"""The range (low, high; None: no bound) of every number a row of `runs.csv` holds; any
`*_ms` column (a stage's milliseconds) is at least 0, and a task declares its own metrics
(`Task.ranges`). A value outside its range, or in an undeclared column, is refused."""
GRANTS = ("rig", "images")
"""What a task's selection may see of the views' geometry: the rig's poses, or the images
and intrinsics only (`bench.frontend.geometry`)."""


@dataclass(frozen=True)
class Method:
    """A row's `policy`: how it is shown and what it is for."""

    name: str
    label: str
    role: str
    whole_pool: bool = False
    """Runs once per scene and seed, as budget 0 (the whole pool, or COLMAP's default)."""
    reads: tuple[str, ...] = ()
    """The front-end signals it reads (for its reported cost)."""
    pool: str = ""
    """The detector whose candidate pool it needs (a grid on another pool leaves it out);
    empty: any pool."""


@dataclass(frozen=True)
class Task:
    """A reconstruction task: what its selection may see and what its rows must hold."""

    name: str
    grant: str
    """`rig` or `images` (`GRANTS`)."""
    needs: tuple[str, ...]
    """The metrics an `ok` row must have."""
    columns: tuple[str, ...]
    """Its metrics in Table 1 (a task other than the headline's as `<task>_<metric>`)."""
    peers: bool = False
    """Whether the stock-COLMAP peers run it (they have no known-pose mode)."""
    doc: str = ""
    ranges: dict[str, tuple[float, float | None]] = field(default_factory=dict)
    """The range of each metric of its own that `RANGES` does not declare."""
    headline: tuple[str, ...] = ()
    """The metrics the report compares methods in: `paired.csv` and `table2.csv`, the
    figures and the page; its first is the one the results page shows paired and the one
    `transfer.csv` ranks by."""
    lower_better: tuple[str, ...] = ()
    """Its metrics where lower is better (the paired wins and the best baseline)."""
    summary: tuple[str, ...] = ()
    """Its metrics in `table_scenes.csv` and, for a task the peers run, in the paired
    comparison with them (`paired_sfm.csv`); empty: the headline."""
    titles: dict[str, str] = field(default_factory=dict)
    """The figures' panel title of each metric they draw, in drawing order (a headline
    metric without one is drawn under its column name)."""
    exclusion_reference: bool = False
    """Whether a (scene, seed) that stock COLMAP with all its features (`REFERENCE_PEER`)
    does not map is left out of this task's means and paired differences (the task's
    rows hold `registered_views` and `maa`, `REFERENCE_MAPS`; the peers run it)."""


@dataclass(frozen=True)
class Unit:
    """One unit of work: a method at a budget in one scene and seed."""

    scene: str
    seed: int
    method: str
    budget: int

    @property
    def group(self) -> tuple[str, int]:
        """(scene, seed): the render entry and front end the unit reads."""
        return self.scene, self.seed

    def __str__(self) -> str:
        return f"{self.scene} s{self.seed} {self.method} b{self.budget}"


class Job(NamedTuple):
    """One row of a unit: a task under a track protocol."""

    task: str
    protocol: str

    @property
    def key(self) -> str:
        """`task/protocol`: the job's entry in its unit's `prediction.json`."""
        return f"{self.task}/{self.protocol}"


METHODS: dict[str, Method] = {}
TASKS: dict[str, Task] = {}
CODE: dict[str, tuple] = {}
"""The functions that implement each method: the roots of its rows' code hash."""
SETTINGS: dict[str, type] = {}
"""The dataclass of each method's own settings (a method without one has none)."""


def declare_method(method: Method, code: tuple = (), settings: type | None = None) -> Method:
    """Register a method under a name no other method has, with the functions that
    implement it and the dataclass of its own settings (if it has any)."""
    if method.role not in ROLES:
        raise BenchError(
            f"policy {method.name}: unknown role {method.role!r}; valid: {', '.join(ROLES)}"
        )
    if method.name in METHODS:
        raise BenchError(f"policy name {method.name!r} is taken; give the policy another name")
    METHODS[method.name] = method
    CODE[method.name] = tuple(code)  # a name declared anew starts from its own code only
    SETTINGS.pop(method.name, None)
    if settings is not None:
        SETTINGS[method.name] = settings
    return method


def implemented_by(names, *functions) -> None:
    """Record the functions that implement the declared methods `names` (module
    docstring); a method declared before its functions are defined names them here."""
    for name in names:
        CODE[name] = CODE.get(name, ()) + functions


def declare_task(task: Task) -> Task:
    """Register a task under a name no other task has."""
    if task.grant not in GRANTS:
        raise BenchError(f"task {task.name}: unknown grant {task.grant!r}")
    if task.name in TASKS:
        raise BenchError(f"task name {task.name!r} is taken; give the task another name")
    TASKS[task.name] = task
    return task


@dataclass(frozen=True)
class Vocabulary:
    """The methods and tasks a set of rows was computed under; what the report reads."""

    methods: dict[str, Method] = field(default_factory=dict)
    tasks: dict[str, Task] = field(default_factory=dict)

    @classmethod
    def current(cls) -> Vocabulary:
        """The declarations of this process (the compute stages imported)."""
        return cls(dict(METHODS), dict(TASKS))

    def label(self, policy: str) -> str:
        m = self.methods.get(policy)
        return m.label if m else policy

    def column(self, task: str, metric: str) -> str:
        """A task's metric as the report's tables name it: bare for the headline task,
        `<task>_<metric>` for another (`bench.report.tables.headline_frame`)."""
        return metric if task == HEADLINE[0] else f"{task}_{metric}"

    def headline_metrics(self) -> list[str]:
        """Every task's headline metrics (`Task.headline`), as the tables name them."""
        return [self.column(n, m) for n, t in self.tasks.items() for m in t.headline]

    def first_headline(self) -> list[str]:
        """Each task's first headline metric (the page's and the transfer's)."""
        return [self.column(n, t.headline[0]) for n, t in self.tasks.items() if t.headline]

    def summary_metrics(self, task: str) -> list[str]:
        """A task's metrics in the per-scene table and the peer comparison."""
        t = self.tasks[task]
        return [self.column(task, m) for m in t.summary or t.headline]

    def lower_better(self) -> set[str]:
        """The metrics (as the tables name them) where lower is better."""
        return {self.column(n, m) for n, t in self.tasks.items() for m in t.lower_better}

    def panels(self) -> list[tuple[str, str]]:
        """(metric, title) of every panel the figures draw: each task's titled metrics,
        then its headline metrics without a title, under their names."""
        out = []
        for n, t in self.tasks.items():
            titled = {**t.titles, **{m: t.titles.get(m, m) for m in t.headline}}
            out += [(self.column(n, m), title) for m, title in titled.items()]
        return list(dict(out).items())

    @property
    def posefree_task(self) -> str | None:
        """The first task whose selection sees the images only (`GRANTS`), if any."""
        return next((n for n, t in self.tasks.items() if t.grant == GRANTS[1]), None)

    @property
    def exclusion_tasks(self) -> list[str]:
        """The tasks whose means leave out the cells stock COLMAP does not map."""
        return [n for n, t in self.tasks.items() if t.exclusion_reference]

    def split(self, column: str) -> tuple[str, str]:
        """(task, metric) of a table column (`column`'s inverse): another task's if its
        name and `_` prefix the column, else the headline task's."""
        for n in self.tasks:
            if n != HEADLINE[0] and column.startswith(f"{n}_"):
                return n, column[len(n) + 1 :]
        return HEADLINE[0], column

    def excluded(self, column: str) -> bool:
        """Whether a table column is a metric of a task with the exclusion rule."""
        task = self.tasks.get(self.split(column)[0])
        return bool(task and task.exclusion_reference)

    def with_role(self, *roles: str) -> list[str]:
        return [n for n, m in self.methods.items() if m.role in roles]

    def order(self, policy: str) -> tuple[int, int]:
        """Display order: baselines, contenders, references, peers; then declaration."""
        names = list(self.methods)
        if policy not in self.methods:
            return len(ROLES), 0
        return ROLES.index(self.methods[policy].role), names.index(policy)

    def range_of(self, column: str) -> tuple[float, float | None] | None:
        """The declared range of a number column of `runs.csv` (None: undeclared)."""
        for task in self.tasks.values():
            if column in task.ranges:
                return task.ranges[column]
        return RANGES.get(column, AT_LEAST_0 if column.endswith("_ms") else None)

    def merged(self, older: Vocabulary) -> Vocabulary:
        """This vocabulary, keeping `older`'s entries for names it does not declare."""
        return Vocabulary(older.methods | self.methods, older.tasks | self.tasks)

    def to_json(self) -> str:
        return json.dumps(
            {
                "methods": {n: asdict(m) for n, m in self.methods.items()},
                "tasks": {n: asdict(t) for n, t in self.tasks.items()},
            },
            indent=1,
        )

    @classmethod
    def from_json(cls, text: str) -> Vocabulary:
        data = json.loads(text)
        methods = {
            n: Method(**{**m, "reads": tuple(m["reads"])}) for n, m in data["methods"].items()
        }
        tasks = {
            n: Task(
                **{
                    **t,
                    "needs": tuple(t["needs"]),
                    "columns": tuple(t["columns"]),
                    **{f: tuple(t.get(f, ())) for f in ("headline", "lower_better", "summary")},
                    "ranges": {k: tuple(r) for k, r in t.get("ranges", {}).items()},
                }
            )
            for n, t in data["tasks"].items()
        }
        return cls(methods, tasks)

    @classmethod
    def load(cls, results: Path) -> Vocabulary:
        """The vocabulary recorded in a results folder (`vocabulary.json`); one recorded
        before tasks declared what the report reads of them (`REPORT_FIELDS`) is refused,
        with `bench upgrade` as the remedy."""
        path = Path(results) / VOCABULARY_FILE
        try:
            text = path.read_text()
            tasks = json.loads(text)["tasks"].values()
            older = sorted({f for t in tasks for f in REPORT_FIELDS if f not in t})
            if older:
                raise BenchError(
                    f"{path} was written by an older bench (its tasks lack {', '.join(older)}); "
                    f"`bench upgrade --results {results}` brings the folder up to date"
                )
            return cls.from_json(text)
        except FileNotFoundError:
            raise BenchError(
                f"{path} not found: these results were not written by this version of "
                "`bench run`; run it into the folder again"
            ) from None
        except (ValueError, KeyError, TypeError) as e:
            raise BenchError(f"{path} is unreadable ({type(e).__name__}: {e})") from None


VOCABULARY_FILE = "vocabulary.json"
REPORT_FIELDS = ("headline", "lower_better", "summary", "titles", "exclusion_reference")
"""What the report reads of a task (`Task`); a recorded vocabulary without them is older."""
