"""Render noise, the lever of issue 28 point 1: how many of a render's SIFT candidates are
made by path-tracing noise, and what more samples or a denoiser do to them and to the
candidates that are real, per scene, against a reference render of the same view.

    .venv/bin/python benchmarks/render_noise.py [--scenes corridor,facade,table,vegetation]
        [--seed 0] [--view 0] [--spp 25,64,128] [--ref-spp 512] [--denoise 3,5]

For each scene and each setting (`spp`, or the default spp followed by OpenCV's
non-local-means denoiser of strength `h`, `cv2.fastNlMeansDenoisingColored`):

- `seconds`: render (and denoise) time of the view on this machine;
- `candidates_per_mp`: SIFT candidates (the pool's detector, uncapped) per megapixel;
- `noise_pct`: candidates with no candidate within 1 px in the reference render (made by
  noise: a photograph of the same scene would not have them);
- `kept_pct`: reference candidates with a candidate within 1 px (the real structure the
  setting keeps).

The reference is rendered once per scene at `--ref-spp`; nothing is cached.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from bench.camera import Camera
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.views import View
from bench.render.config import RenderConfig
from bench.render.mitsuba import render_view, srgb8
from bench.render.variant import resolve_variant
from bench.scenes.catalog import build_scene, load_spec

UNCAPPED = DetectorConfig(max_features=10**7)


def near(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each point of `a` has a point of `b` within 1 px."""
    if len(b) == 0:
        return np.zeros(len(a), bool)
    d, _ = cKDTree(b).query(a, distance_upper_bound=1.0)
    return np.isfinite(d)


def render(desc, view: int, cfg: RenderConfig, variant: str) -> tuple[np.ndarray, float]:
    t = time.perf_counter()
    rgb, _, _ = render_view(desc, view, cfg, variant)
    return srgb8(rgb), time.perf_counter() - t


def measure(image: np.ndarray, camera: Camera, ref_xy: np.ndarray) -> dict:
    xy = detect(View(0, "v", image, camera), UNCAPPED).xy
    mp = camera.width * camera.height / 1e6
    return {
        "candidates_per_mp": len(xy) / mp,
        "noise_pct": 100.0 * float((~near(xy, ref_xy)).mean()) if len(xy) else 0.0,
        "kept_pct": 100.0 * float(near(ref_xy, xy).mean()) if len(ref_xy) else 0.0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="corridor,facade,table,vegetation")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--view", type=int, default=0)
    ap.add_argument("--spp", default="25,64,128", help="sample counts to compare")
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--denoise", default="3,5", help="NL-means strengths h on the default spp")
    ap.add_argument("--renders", type=Path, default=Path("renders"), help="variant probe memo")
    args = ap.parse_args()
    base = RenderConfig()
    args.renders.mkdir(parents=True, exist_ok=True)
    variant, _ = resolve_variant(base.variant, args.renders)
    rows = []
    for scene in [s for s in args.scenes.split(",") if s]:
        desc = build_scene(load_spec(scene), args.seed, base.width, base.height, base.views)
        camera = desc.cameras[args.view]
        ref, _ = render(desc, args.view, RenderConfig(spp=args.ref_spp), variant)
        ref_xy = detect(View(0, "ref", ref, camera), UNCAPPED).xy
        for spp in [int(s) for s in args.spp.split(",") if s]:
            img, sec = render(desc, args.view, RenderConfig(spp=spp), variant)
            rows.append({"scene": scene, "setting": f"{spp} spp", "seconds": sec})
            rows[-1] |= measure(img, camera, ref_xy)
            if spp == base.spp:
                default = (img, sec)
            print(rows[-1], flush=True)
        for h in [float(s) for s in args.denoise.split(",") if s]:
            t = time.perf_counter()
            img = cv2.fastNlMeansDenoisingColored(default[0], None, h, h, 7, 21)
            sec = default[1] + time.perf_counter() - t
            rows.append({"scene": scene, "setting": f"{base.spp} spp + NL-means h={h:g}"})
            rows[-1] |= {"seconds": sec, **measure(img, camera, ref_xy)}
            print(rows[-1], flush=True)
    print(pd.DataFrame(rows).to_string(index=False, float_format="%.3g"))


if __name__ == "__main__":
    main()
