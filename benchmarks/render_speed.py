"""Render-stage timings: seconds per view (auto variant and scalar_rgb), the stage's overhead
over a bare `mitsuba.render` of the same scene dictionaries, and a cache hit.

    .venv/bin/python benchmarks/render_speed.py [--scene table] [--views 6]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench import render
from bench.config import RenderConfig
from bench.scene import build_scene, load_spec
from bench.variant import resolve_variant


def bare_seconds(scene: str, cfg: RenderConfig, variant: str, views: int) -> float:
    """Per-view seconds of load_dict + render alone, on the same dictionaries."""
    import mitsuba as mi

    mi.set_variant(variant)
    desc = build_scene(load_spec(scene), 0, cfg.width, cfg.height)
    t = time.perf_counter()
    for v in range(views):
        mi.render(mi.load_dict(render.mitsuba_scene_dict(desc, v, cfg)), seed=v).numpy()
    return (time.perf_counter() - t) / views


def stage_seconds(scene: str, cfg: RenderConfig, views: int, tmp: Path) -> float:
    n = render.N_VIEWS
    render.N_VIEWS = views
    try:
        t = time.perf_counter()
        render.render_scene(scene, 0, cfg, tmp, force=True)
        return (time.perf_counter() - t) / views
    finally:
        render.N_VIEWS = n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="table")
    ap.add_argument("--views", type=int, default=6)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        auto, _ = resolve_variant("auto", tmp)
        for variant in dict.fromkeys([auto, "scalar_rgb"]):
            cfg = RenderConfig(variant=variant)
            bare_seconds(a.scene, cfg, variant, 1)  # warm-up: kernel compilation, caches
            # interleaved, so that drift of the machine affects both alike
            stage = (
                stage_seconds(a.scene, cfg, a.views, tmp)
                + stage_seconds(a.scene, cfg, a.views, tmp)
            ) / 2
            bare = (
                bare_seconds(a.scene, cfg, variant, a.views)
                + bare_seconds(a.scene, cfg, variant, a.views)
            ) / 2
            print(
                f"{a.scene} {variant}: stage {stage:.2f} s/view, bare mitsuba.render {bare:.2f} s/view, overhead {100 * (stage / bare - 1):+.1f}%"
            )
        cfg = RenderConfig(variant=auto)
        render.render_scene(a.scene, 0, cfg, tmp)
        t = time.perf_counter()
        render.render_scene(a.scene, 0, cfg, tmp)
        print(f"cache hit for the whole scene: {1000 * (time.perf_counter() - t):.0f} ms")


if __name__ == "__main__":
    main()
