"""How a scene is rendered: a typed configuration whose field docstrings are `--help` text."""

from __future__ import annotations

from dataclasses import dataclass

VARIANTS = ("auto", "cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
MAX_VIEWS = 256
"""The most views the command line renders on a path (`bench.cli.common.checked_views`):
twelve times the dense regime's 21, far beyond any grid (each view is a path-traced image
with its ground-truth layers, seconds and megabytes); 100000 started rendering."""


@dataclass(frozen=True)
class RenderConfig:
    """How a scene is rendered; every field changes pixels, so all enter the cache key."""

    views: int = 6
    """Cameras per scene, evenly on the scene's camera path (`bench scenes` describes each
    path): more views, longer tracks and more pairs, at more render and run time."""
    width: int = 640
    """Image width in pixels."""
    height: int = 480
    """Image height in pixels."""
    spp: int = 25
    """Samples per pixel (multi-jittered) for the path-traced image and the ground-truth
    layers, which come from the same pass."""
    max_depth: int = 3
    """Longest light path the path tracer follows (3 = direct light and one bounce)."""
    denoise: float = 2.0
    """How the exposure is developed into the image (`bench.render.develop`): the strength of
    the denoiser applied to its light, in multiples of the noise measured in each view (0:
    none). Photographs carry no Monte Carlo noise; a camera denoises before it encodes. 2
    was chosen by a rule stated before the full grid ran (docs/scenes.md, "Render noise")."""
    variant: str = "auto"
    """Mitsuba variant: auto (cuda_ad_rgb if a GPU renders, else llvm_ad_rgb if a probe
    renders, else scalar_rgb), or one of them by name."""

    def validate(self) -> RenderConfig:
        from bench import BenchError

        if self.views < 2:
            raise BenchError(f"views must be at least 2, got {self.views}")
        for name in ("width", "height", "spp", "max_depth"):
            if getattr(self, name) <= 0:
                raise BenchError(f"{name} must be positive, got {getattr(self, name)}")
        if not self.denoise >= 0:
            raise BenchError(f"denoise must be at least 0, got {self.denoise}")
        if self.variant not in VARIANTS:
            raise BenchError(f"unknown variant {self.variant!r}; valid: {', '.join(VARIANTS)}")
        return self


QUICK_RENDER = RenderConfig(width=320, height=240, spp=9, max_depth=2)
"""The tiny render of `--quick` runs and of the tests."""
