"""The settings that decide a run's rows (`RunConfig`), stored beside the results
(`config.json`). The shared ones decide every row and bind the results folder; a
method's own settings (`bench.vocabulary.SETTINGS`) decide its rows alone
(`bench.harness.keys.prediction_hash`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from bench import BenchError
from bench.backend.matching import BackendConfig, check_matcher
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import SignalConfig
from bench.frontend.policies import PolicyConfig, check_methods, own_fields, settings_for
from bench.render.config import RenderConfig
from bench.vocabulary import METHODS, MULTI_VIEW, PER_VIEW, SETTINGS

MAX_ADDED = 8
"""The most views the nbv task adds (its metrics are declared for k = 0 to this)."""


@dataclass(frozen=True)
class NbvConfig:
    """The next-views task (`--tasks nbv`, `bench.unit.nbv`): from an initial capture,
    a view chooser adds views one at a time from the candidate poses of the planned path."""

    policy: str = "cross-view"
    """The keypoint policy in every view, at the grid's budgets: the per-view pose-free
    policy with the highest sfm mAA at 256 in the published sparse snapshot (cross-view,
    0.62; results/published/table1.csv; the multi-view track-first ranks above it there,
    0.98)."""
    added: tuple[int, ...] = (1, 2, 4)
    """After how many added views the capture is scored (increasing, 1 to 8); the report's
    headline is the gain at 2."""
    initial: int = 6
    """A rendered scene's initial capture: this many views evenly on its path (6: the sparse
    regime's rig)."""
    between: int = 3
    """A rendered scene's candidates: this many path positions between consecutive initial
    views, rendered when chosen (3: the dense regime's 21-view path)."""
    every: int = 2
    """A dataset's initial capture: every m-th image of its model (name order), the first
    included; the others, with their model poses, are the candidates."""

    @property
    def path(self) -> int:
        """Views on a rendered scene's path (the initial capture and the candidates)."""
        return (self.initial - 1) * (self.between + 1) + 1

    def validate(self) -> NbvConfig:
        added = list(self.added)
        if not added or added != sorted(set(added)) or not 1 <= added[0] <= added[-1] <= MAX_ADDED:
            raise BenchError(
                f"nbv.added must be increasing numbers of views from 1 to {MAX_ADDED}, got {added}"
            )
        if self.initial < 3 or self.between < 1 or self.every < 2:
            raise BenchError(
                "nbv.initial must be at least 3 (a track of three views), nbv.between at "
                f"least 1 and nbv.every at least 2; got {self.initial}, {self.between}, {self.every}"
            )
        if (self.initial - 1) * self.between < added[-1]:
            raise BenchError(
                f"nbv.added goes up to {added[-1]} views, but the path has "
                f"{(self.initial - 1) * self.between} candidates; raise nbv.between"
            )
        check_methods([self.policy])
        method = METHODS[self.policy]
        if method.kind not in (PER_VIEW, MULTI_VIEW) or method.whole_pool:
            raise BenchError(
                f"nbv.policy must be a budgeted selection policy, not {self.policy} ({method.kind})"
            )
        return self


QUICK_NBV = NbvConfig(between=1)
"""The nbv task of `--quick` runs: five candidates on an 11-view path."""


PREDICTION = ("detector", "signals", "policy", "backend")
"""The sections of the settings a unit's prediction reads: the front end's, the
selection's and the back end's (the render settings decide the render entry, which a row
records as its `render_key`)."""
METHODS_SECTION = "methods"
"""The key of the methods' own settings in `RunConfig.as_dict` (and `config.json`)."""


@dataclass(frozen=True)
class RunConfig:
    """The settings that decide a run's metrics; each section is reachable on the command
    line as `--set section.field=value`, a method's own settings as
    `--set <method>.<field>=value`."""

    render: RenderConfig | None = field(default_factory=RenderConfig)
    """None for a dataset, whose images are not rendered."""
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    signals: SignalConfig = field(default_factory=SignalConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)
    nbv: NbvConfig = field(default_factory=NbvConfig)
    methods: dict[str, dict] = field(default_factory=dict)
    """Each method's own settings that differ from their defaults, by method name."""

    def shared(self) -> dict:
        """The settings that decide every row: all of them but the policy modules (whose
        content decides their own policies' rows only) and the methods' own."""
        settings = asdict(self)
        del settings["policy"]["modules"], settings[METHODS_SECTION]
        return settings

    def prediction(self, extra: tuple[str, ...] = ()) -> dict:
        """The shared settings a task's predicted rows read: `PREDICTION` and `extra` (the
        task's own sections, `bench.unit.tasks.TaskRunner.settings`)."""
        shared = self.shared()
        return {k: shared[k] for k in (*PREDICTION, *extra)}

    def own(self, method: str) -> dict:
        """A method's own settings, its defaults filled in ({} if it has none)."""
        cls = SETTINGS.get(method)
        if cls is None:
            return {}
        cfg = self.policy_config(method)
        return {k: getattr(cfg, k) for k in own_fields(cls)}

    def policy_config(self, method: str) -> PolicyConfig:
        """The settings `method` is given: the shared policy settings and its own."""
        return settings_for(method, self.policy, self.methods.get(method, {}))

    def with_own(self, method: str, **values) -> RunConfig:
        """These settings with some of `method`'s own settings changed."""
        cls = SETTINGS.get(method)
        valid = own_fields(cls) if cls else []
        for k in values:
            if k not in valid:
                raise BenchError(
                    f"{method} has no setting {k!r}; valid: {', '.join(valid) or 'none'}"
                )
        merged = {**self.methods, method: {**self.methods.get(method, {}), **values}}
        return replace(self, methods=merged)

    def for_method(self, method: str) -> RunConfig:
        """The settings a method's units run under: its pool's detector and its matcher
        where it names them (`Method.pool`, `Method.matcher`: `bench.unit.pooled`), these
        otherwise."""
        m = METHODS[method]
        detector, matcher = m.pool or self.detector.detector, m.matcher or self.backend.matcher
        if (detector, matcher) == (self.detector.detector, self.backend.matcher):
            return self
        return replace(
            self,
            detector=replace(self.detector, detector=detector),
            backend=replace(self.backend, matcher=matcher),
        )

    def as_dict(self) -> dict:
        """The shared settings, and under `methods` each method's own (what
        `config.json` records; the folder is bound to the shared ones alone)."""
        return self.shared() | {METHODS_SECTION: {m: self.own(m) for m in sorted(SETTINGS)}}

    def validate(self) -> RunConfig:
        """Each section's own check (the signals' is here), and each method's."""
        for section in (self.render, self.detector, self.policy, self.backend, self.nbv):
            if section is not None:
                section.validate()
        check_matcher(self.backend, self.detector.detector)
        unknown = sorted(set(self.methods) - set(SETTINGS))
        if unknown:
            raise BenchError(f"{unknown[0]} has no settings of its own")
        for method in SETTINGS:
            self.policy_config(method).validate()
        prior, first = self.signals.depth_prior, self.signals.first_pass
        if (prior is not None and not prior > 0) or first < 8:
            raise BenchError(
                f"signals.depth_prior must be > 0 (or none) and signals.first_pass >= 8, got "
                f"{prior} and {first}"
            )
        return self
