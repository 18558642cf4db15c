"""The settings that decide a run's rows (`RunConfig`), stored beside the results
(`config.json`). The shared ones decide every row and bind the results folder; a
method's own settings (`bench.vocabulary.SETTINGS`) decide its rows alone
(`bench.harness.predict.prediction_hash`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from bench import BenchError
from bench.backend.matching import BackendConfig, check_matcher
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import SignalConfig
from bench.frontend.policies import PolicyConfig, own_fields, settings_for
from bench.harness.declared import package_settings
from bench.render.config import RenderConfig

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
    methods: dict[str, dict] = field(default_factory=dict)
    """Each method's own settings that differ from their defaults, by method name."""

    def shared(self) -> dict:
        """The settings that decide every row: all of them but the policy modules (whose
        content decides their own policies' rows only) and the methods' own."""
        settings = asdict(self)
        del settings["policy"]["modules"], settings[METHODS_SECTION]
        return settings

    def own(self, method: str) -> dict:
        """A method's own settings, its defaults filled in ({} if it has none)."""
        cls = package_settings().get(method)
        if cls is None:
            return {}
        cfg = self.policy_config(method)
        return {k: getattr(cfg, k) for k in own_fields(cls)}

    def policy_config(self, method: str) -> PolicyConfig:
        """The settings `method` is given: the shared policy settings and its own."""
        return settings_for(method, self.policy, self.methods.get(method, {}))

    def with_own(self, method: str, **values) -> RunConfig:
        """These settings with some of `method`'s own settings changed."""
        cls = package_settings().get(method)
        valid = own_fields(cls) if cls else []
        for k in values:
            if k not in valid:
                raise BenchError(
                    f"{method} has no setting {k!r}; valid: {', '.join(valid) or 'none'}"
                )
        merged = {**self.methods, method: {**self.methods.get(method, {}), **values}}
        return replace(self, methods=merged)

    def as_dict(self) -> dict:
        """The shared settings, and under `methods` each method's own (what
        `config.json` records; the folder is bound to the shared ones alone)."""
        return self.shared() | {
            METHODS_SECTION: {m: self.own(m) for m in sorted(package_settings())}
        }

    def validate(self) -> RunConfig:
        """Each section's own check (the signals' is here), and each method's."""
        for section in (self.render, self.detector, self.policy, self.backend):
            if section is not None:
                section.validate()
        check_matcher(self.backend, self.detector.detector)
        unknown = sorted(set(self.methods) - set(package_settings()))
        if unknown:
            raise BenchError(f"{unknown[0]} has no settings of its own")
        for method in package_settings():
            self.policy_config(method).validate()
        prior, first = self.signals.depth_prior, self.signals.first_pass
        if (prior is not None and not prior > 0) or first < 8:
            raise BenchError(
                f"signals.depth_prior must be > 0 (or none) and signals.first_pass >= 8, got "
                f"{prior} and {first}"
            )
        return self
