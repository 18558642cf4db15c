"""Per scene at default settings: render seconds per view (from the cache entries' meta.json)
and SIFT candidate counts per view at the default detector settings.

    .venv/bin/python benchmarks/scene_stats.py [--seed 0]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from bench import ROOT
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.views import load_views
from bench.render.config import RenderConfig
from bench.render.entry import render_scene
from bench.scenes.spec import scene_names


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    total = 0.0
    for name in scene_names():
        entry = render_scene(name, a.seed, RenderConfig(), ROOT / "renders")
        secs = json.loads((entry / "meta.json").read_text())["seconds_per_view"]
        total += sum(secs)
        counts = [len(detect(v, DetectorConfig())) for v in load_views(entry)]
        print(
            f"{name:<11} render {np.mean(secs):5.2f} s/view (min {min(secs):.2f}, max {max(secs):.2f}); SIFT candidates per view {counts}, min/256 = {min(counts) / 256:.1f}x"
        )
    print(f"all scenes: {total:.0f} s for {6 * len(scene_names())} views")


if __name__ == "__main__":
    main()
