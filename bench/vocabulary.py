"""The benchmark's vocabulary, in one place: the keys of a row, the track protocols, the
headline, the units of work, and the registries of methods and tasks.

A method (a selection policy, a reference or a stock-COLMAP peer) is declared where it is
implemented (`bench.frontend.policies.policy`, the feedback loop, the oracle, the peers),
with its display label, its role and its own settings (`SETTINGS`: a
dataclass, set as `--set <method>.<field>=value`); the display names, the baselines, the default grid
and the budget-0 rule are derived from these declarations. A task is declared where its
reconstruction and evaluation are (`bench.unit.tasks`). A results folder records the
vocabulary its rows were computed under (`vocabulary.json`), and the report reads that
record: it never imports the stages that compute.

This module imports nothing heavy, so every stage (and the report) may import it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from typing import NamedTuple

from bench import BenchError

BAG = "bag"
"""The `runs.csv` column naming a row's bag (`Unit.bag`): a dataset's bag, its image
names space-separated; empty for a rendered scene's rows (and a whole dataset's), and in a
folder written before the column was part of the key (read as empty: `bench.runs`)."""
KEY = ("scene", "seed", "method", "budget", BAG, "task", "protocol")
"""The columns that identify a row of `runs.csv`: rows of other bags (another --bag-size
or --bags) live side by side in one folder."""
UNIT_KEY = KEY[:4]
"""The columns that pair the units of one page's rows (one selection, matched once per
geometry): a page reads the bags of one invocation alone, so its seeds name its bags."""
PROTOCOLS = {"multiview": 3, "twoview": 2}
"""Track protocols: the fewest views a point's track may have (`bench.backend.reconstruction`)."""
NO_PROTOCOL = "none"
"""The protocol of the rows of a task without tracks (`Task.tracks`: pairs): one row per
unit, read under every track protocol."""
HEADLINE = ("tri", "multiview")
"""The headline task and track protocol."""
HEADLINE_BUDGET = 256
HEADLINE_POLICY = "adaptive"
"""The paper's method, compared with every baseline in `table2.csv` and `paired.csv`."""
NEXT_VIEWS = "nbv"
"""The next-views task (`bench.unit.nbv`): its gains are Table 3 and `figure_views.png`
(`bench.report.nbv`)."""
FIGURE_SCENE = "table"
"""The scene of Figure 2 (the headline method's selection and its points)."""
PAIRED_PEERS = ("colmap-b", "aliked-b", "disk-b")
"""The peers held to the same budget that `paired_sfm.csv` compares with, where they ran:
stock COLMAP's, and a learned detector's own top-B with LightGlue (on its pool)."""
CATEGORY_PEERS = (*PAIRED_PEERS, "colmap-tracks-b")
"""The peers held to the same budget that each category of `sees` is judged against, where
they ran (`bench.report.categories`, `paired_sfm.csv`): `PAIRED_PEERS`, which see their own
image, and stock COLMAP choosing from its own first pass, which sees other views."""
FRONTIER_PEERS = ("colmap-b", "colmap-tracks-b")
"""Each category's stock-COLMAP peer (its own image; other views) whose curve over the
budgets is a frontier of `figure_cost.png` (`bench.report.cost`)."""
FRONTIER_BUDGETS = (1024, 2048)
"""The budgets at which a regime's grid runs `FRONTIER_PEERS` alone, beside the grid's
budgets, so that each frontier spans 128 to 2048 keypoints per view."""
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
PER_VIEW, MULTI_VIEW, GROUND_TRUTH, OWN_PIPELINE = "per-view", "multi-view", "oracle", "peer"
EQUAL_COUNT = "equal-count"
"""The kind of `<policy>@<peer>`: a per-view policy at a peer's own keypoint count per view
(`bench.backend.equal_count` declares it); the report pairs it with its peer."""
RECOMPUTED_TRUTH = "rendered, recomputed"
"""The `ground_truth` of the rows of a reference entry (`bench.render.reference`): its
layers recomputed on the machine that ran by the AOV pass, which can differ from the
reference machine's in a few pixels' last bits; only the oracle selects with them."""


def equal_parts(name: str) -> tuple[str, str]:
    """(policy, peer) of an equal-count method's name, `<policy>@<peer>`."""
    policy, _, peer = name.rpartition("@")
    return policy, peer


TRACKS_PEER = "peer-tracks"
"""The kind of `colmap-tracks-b`: stock COLMAP choosing each view's keypoints by the views
its own verified tracks span (`bench.backend.peers` declares it; see `KIND_SEES`)."""
TRACKS_FIRST_PASS = 4
"""Its first pass, keypoints per view as a multiple of B: `track-first`'s (its default
`first_pass`, tests/test_tracks_peer.py), so that the two have seen as much."""


WHOLE_POOL_BUDGET = (
    "0: no budget; the whole pool (all) or COLMAP's own count (colmap), run once per scene and seed"
)
KIND_BUDGET: dict[str, str] = {
    PER_VIEW: "the keypoints each view keeps: at most B of its own pool",
    MULTI_VIEW: "the keypoints each view keeps: at most B, chosen from every view's pool at once",
    GROUND_TRUTH: "the keypoints each view keeps: at most B, chosen with the ground truth",
    OWN_PIPELINE: "the keypoints each view keeps of COLMAP's extraction, held to B",
}
"""What the budget column (B) of a method's rows means, by its kind (`budget_means`): named
once here, where the kinds are; a plugin's kind adds its entry (`declare_kind`)."""
KINDS: dict[str, str] = {
    PER_VIEW: "selects from each view's candidate pool alone (`@policy`)",
    MULTI_VIEW: "selects from every view's pool at once, may match its own selections "
    "(`@multiview_policy`: adaptive-loop)",
    GROUND_TRUTH: "selects from the pools with the ground truth: a reference of the "
    "evaluation side, never a policy (the oracle)",
    OWN_PIPELINE: "extracts, matches and maps with a pipeline of its own (stock COLMAP)",
}
"""How a method works, which decides how its units are run (`bench.unit.methods`: one
runner per kind) and whether `bench select` can run it; a plugin declares a new kind with
`declare_kind` and its runner with `bench.unit.methods.register_kind`."""
IMAGE, VIEWS, TRUTH = "image", "views", "truth"
SEES = {
    IMAGE: "its own view's image (and the intrinsics): the field's rule, one keypoint list "
    "per image, shared by every pair and every bag",
    VIEWS: "other views of the capture: a first pass matched keypoints of every view "
    "before it chose",
    TRUTH: "the ground truth: a reference of the evaluation side, never a policy",
}
"""What a method's selection sees (`sees`), derived from its kind (`KIND_SEES`) and the
signals it reads (`VIEW_SIGNALS`), never declared apart: each category is judged against a
peer that sees what it sees."""
VIEW_SIGNALS = ("ambiguity", "parallax", "epipolar")
"""The signals that read other views: their candidates and the geometry between views, from
the rig's poses or a first pass of matches (`bench.frontend.signals.GEOMETRIC`)."""
KIND_SEES: dict[str, str] = {
    PER_VIEW: IMAGE,
    MULTI_VIEW: VIEWS,
    GROUND_TRUTH: TRUTH,
    OWN_PIPELINE: IMAGE,
    EQUAL_COUNT: IMAGE,
    TRACKS_PEER: VIEWS,
}
"""What the methods of each kind see at least (`sees`); a kind without an entry (the view
choosers) selects no keypoints and sees nothing here. A plugin's kind adds its entry."""
PERCENT, FRACTION, DEGREES, AT_LEAST_0 = (0.0, 100.0), (0.0, 1.0), (0.0, 180.0), (0.0, None)
GRANTS = ("rig", "images")
"""What a task's selection may see of the views' geometry: the rig's poses, or the images
and intrinsics only (`bench.frontend.geometry`)."""
DISPLAY = {"display": True}
"""The metadata of a declaration's display field: what the report shows, never what
decides a row's values (`deciding`: what a row's cache key holds of a declaration)."""


def deciding(declaration) -> dict:
    """The fields of a declaration (`Method`, `Task`, `Metric`) that decide a row's values:
    all but its display fields."""
    return {
        f.name: getattr(declaration, f.name)
        for f in fields(declaration)
        if not f.metadata.get("display")
    }


@dataclass(frozen=True)
class Metric:
    """A number a row of `runs.csv` holds, declared once, where it is computed: everything
    the runs contract, the tables, the figures, the results page and the transfer table
    read of it. A task names the metrics it reports (`Task.metrics`)."""

    name: str
    range: tuple[float, float | None] = AT_LEAST_0
    """(low, high; None: no bound): a value outside it is refused (`bench.results`)."""
    lower_better: bool = field(default=False, metadata=DISPLAY)
    """Its direction: the paired wins, the best baseline, the transfer's ranking."""
    title: str = field(default="", metadata=DISPLAY)
    """Its panel title in the figures (empty: its name)."""
    failure: float | None = None
    """What a run scores whose method failed (raised, broke its contract, lost its worker):
    nothing was computed, so its rows hold this value and every mean counts it (mAA 0,
    completeness 0). None: such a run has no value, and a mean over a method's runs
    where one failed so is incomplete (not ranked)."""
    of_model: bool = False
    """Measured on the reconstructed points alone: a run whose task failed has none (rmse,
    median error)."""
    peers: bool = field(default=False, metadata=DISPLAY)
    """Whether a stock-COLMAP peer's rows hold it (the metrics of a peer's own keypoints
    and matches: `bench.unit.evaluate.own_pipeline_shared`)."""
    share_of: str = field(default="", metadata=DISPLAY)
    """The report's own: this metric is `share_of` as a percentage of the ground-truth
    method's (`GROUND_TRUTH`) in the same scene, seed, budget, task and protocol."""
    doc: str = field(default="", metadata=DISPLAY)


@dataclass(frozen=True)
class Method:
    """A row's `policy`: how it is shown and what it is for (display fields: `DISPLAY`)."""

    name: str
    label: str = field(metadata=DISPLAY)
    role: str = field(metadata=DISPLAY)
    whole_pool: bool = False
    """Runs once per scene and seed, as budget 0 (`WHOLE_POOL_BUDGET`, `budget_means`)."""
    reads: tuple[str, ...] = ()
    """The front-end signals it reads (for its reported cost)."""
    pool: str = ""
    """The detector whose candidate pool it needs (a grid on another pool leaves it out);
    empty: any pool."""
    kind: str = PER_VIEW
    """How it works (`KINDS`)."""
    matcher: str = ""
    """The back end's matcher its selections are matched with (`backend.matcher`; empty:
    the run's setting)."""


@dataclass(frozen=True)
class Task:
    """A reconstruction task: what its selection may see and what its rows must hold
    (display fields: `DISPLAY`)."""

    name: str
    grant: str
    """`rig` or `images` (`GRANTS`)."""
    needs: tuple[str, ...]
    """The metrics an `ok` row must have."""
    metrics: tuple[str, ...]
    """The metrics it reports (each declared: `Metric`), in Table 1's order (a task other
    than the headline's as `<task>_<metric>`)."""
    peers: bool = False
    """Whether the stock-COLMAP peers run it (they have no known-pose mode)."""
    doc: str = field(default="", metadata=DISPLAY)
    headline: tuple[str, ...] = field(default=(), metadata=DISPLAY)
    """The metrics the report compares methods in: `paired.csv` and `table2.csv`, the
    figures and the page; its first is the one the results page shows paired and the one
    `transfer.csv` ranks by."""
    summary: tuple[str, ...] = field(default=(), metadata=DISPLAY)
    """Its metrics in `table_scenes.csv` and, for a task the peers run, in the paired
    comparison with them (`paired_sfm.csv`); empty: the headline."""
    drawn: tuple[str, ...] = field(default=(), metadata=DISPLAY)
    """The metrics the figures draw (each under its `Metric.title`), in drawing order,
    before the headline metrics not among them."""
    exclusion_reference: bool = field(default=False, metadata=DISPLAY)
    """Whether a (scene, seed) that stock COLMAP with all its features (`REFERENCE_PEER`)
    does not map is left out of this task's means and paired differences (the task's
    rows hold `registered_views` and `maa`, `REFERENCE_MAPS`; the peers run it)."""
    tracks: bool = True
    """Whether the track protocol applies (`PROTOCOLS`): a task without tracks (pairs)
    writes one row per unit, its protocol `NO_PROTOCOL`."""


@dataclass(frozen=True)
class Unit:
    """One unit of work: a method at a budget in one scene and seed (of a dataset scored in
    bags, one bag)."""

    scene: str
    seed: int
    method: str
    budget: int
    bag: str = ""
    """A dataset's bag (`bench.unit.bags`): its image names, space-separated, the row
    column `bag`; empty: every view of the entry."""

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
METRICS: dict[str, Metric] = {}
SETTINGS: dict[str, type] = {}
"""The dataclass of each method's own settings (a method without one has none)."""


def declare_method(method: Method, settings: type | None = None) -> Method:
    """Register a method under a name no other method has, with the dataclass of its own
    settings (if it has any)."""
    if method.role not in ROLES:
        raise BenchError(
            f"policy {method.name}: unknown role {method.role!r}; valid: {', '.join(ROLES)}"
        )
    if method.kind not in KINDS:
        raise BenchError(
            f"method {method.name}: unknown kind {method.kind!r}; valid: {', '.join(KINDS)}"
        )
    if method.name in METHODS:
        raise BenchError(f"policy name {method.name!r} is taken; give the policy another name")
    METHODS[method.name] = method
    SETTINGS.pop(method.name, None)
    if settings is not None:
        SETTINGS[method.name] = settings
    return method


def declare_kind(name: str, doc: str, budget: str = "") -> str:
    """Declare a kind of method under a name no other kind has (its runner:
    `bench.unit.methods.register_kind`), with what the budget of its rows means
    (`KIND_BUDGET`; empty: none said)."""
    if name in KINDS:
        raise BenchError(f"kind name {name!r} is taken; give the kind another name")
    KINDS[name] = doc
    if budget:
        KIND_BUDGET[name] = budget
    return name


def budget_means(method: Method) -> str:
    """What the budget column (B) of `method`'s rows means: `WHOLE_POOL_BUDGET` for a
    whole-pool method, else its kind's (`KIND_BUDGET`; empty for a kind that says none)."""
    return WHOLE_POOL_BUDGET if method.whole_pool else KIND_BUDGET.get(method.kind, "")


def sees(method: Method) -> str:
    """What a method's selection sees (`SEES`): its kind's (`KIND_SEES`), and `views` for a
    method of an `image` kind that reads a signal of other views (`VIEW_SIGNALS`)."""
    kind = KIND_SEES.get(method.kind, "")
    if kind == IMAGE and any(s in VIEW_SIGNALS for s in method.reads):
        return VIEWS
    return kind


def declare_metric(metric: Metric) -> str:
    """Register a metric under a name no other metric has; its name."""
    if metric.name in METRICS and METRICS[metric.name] != metric:
        raise BenchError(f"metric name {metric.name!r} is taken; give the metric another name")
    METRICS[metric.name] = metric
    return metric.name


def declare_task(task: Task) -> Task:
    """Register a task under a name no other task has, reporting declared metrics."""
    if task.grant not in GRANTS:
        raise BenchError(f"task {task.name}: unknown grant {task.grant!r}")
    listed = (*task.metrics, *task.needs, *task.headline, *task.summary, *task.drawn)
    unknown = [m for m in listed if m not in METRICS]
    if unknown:
        raise BenchError(f"task {task.name}: undeclared metric {unknown[0]!r} (declare_metric)")
    if task.name in TASKS:
        raise BenchError(f"task name {task.name!r} is taken; give the task another name")
    TASKS[task.name] = task
    return task


@dataclass(frozen=True)
class Vocabulary:
    """The methods and tasks a set of rows was computed under; what the report reads."""

    methods: dict[str, Method] = field(default_factory=dict)
    tasks: dict[str, Task] = field(default_factory=dict)
    metrics: dict[str, Metric] = field(default_factory=dict)
    seen: dict[str, str] = field(default_factory=dict)
    """What each method's selection sees (`sees`), as recorded where it was computed."""

    @classmethod
    def current(cls) -> Vocabulary:
        """The declarations of this process (the compute stages imported)."""
        seen = {n: sees(m) for n, m in METHODS.items()}
        return cls(dict(METHODS), dict(TASKS), dict(METRICS), seen)

    def label(self, method: str) -> str:
        m = self.methods.get(method)
        return m.label if m else method

    def sees(self, method: str) -> str:
        """What a method's selection sees (`SEES`): as recorded, else derived from its
        recorded kind and reads (a vocabulary recorded before `sees`); empty if unknown."""
        if method in self.seen:
            return self.seen[method]
        return sees(self.methods[method]) if method in self.methods else ""

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
        return {
            self.column(n, m)
            for n, t in self.tasks.items()
            for m in t.metrics
            if self.metrics[m].lower_better
        }

    def columns(self, task: str) -> list[str]:
        """A task's metrics as the tables name them, in Table 1's order."""
        return [self.column(task, m) for m in self.tasks[task].metrics]

    def panels(self) -> list[tuple[str, str]]:
        """(metric, title) of every panel the figures draw: each task's drawn metrics,
        then its headline metrics not among them (`Task.drawn`, `Metric.title`)."""
        out = []
        for n, t in self.tasks.items():
            for m in dict.fromkeys((*t.drawn, *t.headline)):
                out.append((self.column(n, m), self.metrics[m].title or m))
        return list(dict(out).items())

    def shares(self) -> dict[str, str]:
        """{metric: the metric it is a share of} for the report's own (`Metric.share_of`)."""
        return {n: m.share_of for n, m in self.metrics.items() if m.share_of}

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

    def with_kind(self, *kinds: str) -> list[str]:
        return [n for n, m in self.methods.items() if m.kind in kinds]

    def order(self, method: str) -> tuple[int, int]:
        """Display order: baselines, contenders, references, peers; then declaration."""
        names = list(self.methods)
        if method not in self.methods:
            return len(ROLES), 0
        return ROLES.index(self.methods[method].role), names.index(method)

    def range_of(self, column: str) -> tuple[float, float | None] | None:
        """The declared range of a number column of `runs.csv` (None: undeclared); any
        `*_ms` column is at least 0."""
        if column in self.metrics:
            return self.metrics[column].range
        return AT_LEAST_0 if column.endswith("_ms") else None

    def merged(self, older: Vocabulary) -> Vocabulary:
        """This vocabulary, keeping `older`'s entries for names it does not declare."""
        return Vocabulary(
            older.methods | self.methods,
            older.tasks | self.tasks,
            older.metrics | self.metrics,
            older.seen | self.seen,
        )

    def to_json(self) -> str:
        return json.dumps(
            {
                "methods": {n: asdict(m) | {"sees": self.sees(n)} for n, m in self.methods.items()},
                "tasks": {n: asdict(t) for n, t in self.tasks.items()},
                "metrics": {n: asdict(m) for n, m in self.metrics.items()},
            },
            indent=1,
        )

    @classmethod
    def from_json(cls, text: str) -> Vocabulary:
        data = json.loads(text)
        seen = {n: m.pop("sees") for n, m in data["methods"].items() if "sees" in m}
        methods = {
            n: Method(**{**m, "reads": tuple(m["reads"])}) for n, m in data["methods"].items()
        }
        lists = ("needs", "metrics", "headline", "summary", "drawn")
        tasks = {
            n: Task(**{**t, **{f: tuple(t[f]) for f in lists}}) for n, t in data["tasks"].items()
        }
        metrics = {
            n: Metric(**{**m, "range": tuple(m["range"])}) for n, m in data["metrics"].items()
        }
        return cls(methods, tasks, metrics, seen)


def older_fields(data: dict) -> list[str]:
    """What a recorded vocabulary lacks of this one's declarations (a field of a method or
    a task, the metrics): empty where it is current."""
    fields_of = {"methods": Method, "tasks": Task}
    missing = [
        f"{section} field {f.name}"
        for section, cls in fields_of.items()
        for f in fields(cls)
        if any(f.name not in entry for entry in data.get(section, {}).values())
    ]
    return sorted(set(missing)) + ([] if "metrics" in data else ["metrics"])
