"""The settings that decide a run's rows (`RunConfig`), stored beside the results
(`config.json`) and hashed into every row (`bench.harness.predict.prediction_hash`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from bench import BenchError
from bench.backend.matching import BackendConfig
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import SignalConfig
from bench.frontend.policies import PolicyConfig
from bench.render.config import RenderConfig


@dataclass(frozen=True)
class RunConfig:
    """The settings that decide a run's metrics; each section is reachable on the command
    line as `--set section.field=value`."""

    render: RenderConfig | None = field(default_factory=RenderConfig)
    """None for a dataset, whose images are not rendered."""
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    signals: SignalConfig = field(default_factory=SignalConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)

    def as_dict(self) -> dict:
        """The settings that decide every row: all of them but the policy modules, whose
        content decides their own policies' rows only."""
        settings = asdict(self)
        del settings["policy"]["modules"]
        return settings

    def validate(self) -> RunConfig:
        """Each section's own check (the signals' is here)."""
        for section in (self.render, self.detector, self.policy, self.backend):
            if section is not None:
                section.validate()
        prior, first = self.signals.depth_prior, self.signals.first_pass
        if (prior is not None and not prior > 0) or first < 8:
            raise BenchError(
                f"signals.depth_prior must be > 0 (or none) and signals.first_pass >= 8, got "
                f"{prior} and {first}"
            )
        return self
