"""Render-stage timings: seconds per view (auto variant and scalar_rgb), the stage's overhead
over the Mitsuba calls inside it (`load_dict` + `render` of the same scene dictionaries,
timed within the same run, so machine drift cannot bias the ratio), and a cache hit.

    .venv/bin/python benchmarks/render_speed.py [--scene table] [--views 6]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench.render import entry as render
from bench.render.config import RenderConfig
from bench.render.variant import resolve_variant


def stage_timing(scene: str, cfg: RenderConfig, tmp: Path) -> tuple[float, float]:
    """(stage seconds per view, seconds per view inside mitsuba's load_dict + render)."""
    import mitsuba as mi

    inside = [0.0]
    real_load, real_render = mi.load_dict, mi.render

    def timed(fn):
        def wrapper(*args, **kwargs):
            t = time.perf_counter()
            out = fn(*args, **kwargs)
            if fn is real_render:
                out.numpy()  # force evaluation inside the timed call
            inside[0] += time.perf_counter() - t
            return out

        return wrapper

    mi.load_dict, mi.render = timed(real_load), timed(real_render)
    try:
        t = time.perf_counter()
        render.render_scene(scene, 0, cfg, tmp, force=True)
        total = time.perf_counter() - t
    finally:
        mi.load_dict, mi.render = real_load, real_render
    return total / cfg.views, inside[0] / cfg.views


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="table")
    ap.add_argument("--views", type=int, default=6)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        auto, _ = resolve_variant("auto", tmp)
        for variant in dict.fromkeys([auto, "scalar_rgb"]):
            cfg = RenderConfig(variant=variant, views=a.views)
            stage, inside = stage_timing(a.scene, cfg, tmp)
            print(
                f"{a.scene} {variant}: {stage:.2f} s/view for the stage, {inside:.2f} s/view in "
                f"mitsuba load_dict + render, overhead {100 * (stage / inside - 1):.1f}%"
            )
        cfg = RenderConfig(variant=auto, views=a.views)
        render.render_scene(a.scene, 0, cfg, tmp)
        t = time.perf_counter()
        render.render_scene(a.scene, 0, cfg, tmp)
        print(f"cache hit for the whole scene: {1000 * (time.perf_counter() - t):.0f} ms")


if __name__ == "__main__":
    main()
