"""Render noise and its levers (issue 40): how many of a render's SIFT candidates are made
by path-tracing noise under each setting, what the setting keeps of the real structure,
and what it costs per view.

    .venv/bin/python benchmarks/render_noise.py [--scenes corridor,facade,table,vegetation]
        [--seed 0] [--views 0] [--settings 25,64,128,256,25:2,25:3]
        [--contrast 0.01,0.02,0.04] [--ref-spp 512] [--out FILE.csv]

A setting is `SPP` or `SPP:DENOISE` (`RenderConfig.spp`, `RenderConfig.denoise`: the
strength of the developing step's denoiser, `bench.render.develop`); `--contrast` adds the
pool-threshold lever (`detector.sift_contrast`) at the default spp, undenoised. For each
scene, view and setting:

- `noise_pct`: the candidates (the pool's detector, uncapped) with no candidate within
  1 px in the reference: the same view exposed at `--ref-spp` and developed with the same
  setting (a camera with that processing, given an exposure with little noise); the
  measure of `benchmarks/realism.py`. Its floor is the reference's own noise: two
  references of independent noise disagree too (measured: 22 % for two 512-spp exposures
  of the table at the pool's threshold), so a reference far above the settings' spp is
  needed to tell them apart;
- `kept_pct`: reference candidates with a candidate within 1 px (the structure kept);
- `candidates_per_mp`;
- `render_s`, `develop_s`: seconds per view on this machine (exposure, developing step).

The exposure at each spp is rendered once per view and developed with each strength;
nothing is cached.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from bench.frontend.features import DetectorConfig, detect
from bench.frontend.views import View
from bench.render.config import RenderConfig
from bench.render.develop import develop
from bench.render.mitsuba import expose
from bench.render.variant import resolve_variant
from bench.scenes.catalog import build_scene, load_spec


def near(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each point of `a` has a point of `b` within 1 px."""
    if len(b) == 0:
        return np.zeros(len(a), bool)
    d, _ = cKDTree(b).query(a, distance_upper_bound=1.0)
    return np.isfinite(d)


def pool(image: np.ndarray, camera, contrast: float) -> np.ndarray:
    """The candidates' positions (the pool's detector, uncapped)."""
    cfg = DetectorConfig(max_features=10**7, sift_contrast=contrast)
    return detect(View(0, "v", image, camera), cfg).xy


def settings(text: str) -> list[tuple[int, float]]:
    """`SPP[:DENOISE],...` as (spp, denoise) pairs."""
    out = []
    for item in text.split(","):
        spp, _, strength = item.partition(":")
        out.append((int(spp), float(strength or 0)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="corridor,facade,table,vegetation")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--views", default="0", help="view indices of the default rig")
    ap.add_argument("--settings", default="25,64,128,256,25:2,25:3")
    ap.add_argument("--contrast", default="0.01,0.02,0.04", help="pool thresholds (empty: none)")
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--renders", type=Path, default=Path("renders"), help="variant probe memo")
    ap.add_argument("--out", type=Path, default=None, help="also write the rows as CSV")
    args = ap.parse_args()
    base = RenderConfig()
    args.renders.mkdir(parents=True, exist_ok=True)
    variant, _ = resolve_variant(base.variant, args.renders)
    levers = settings(args.settings)
    contrasts = [float(c) for c in args.contrast.split(",") if c]
    rows = []
    for scene in [s for s in args.scenes.split(",") if s]:
        desc = build_scene(load_spec(scene), args.seed, base.width, base.height, base.views)
        for view in [int(v) for v in args.views.split(",")]:
            camera = desc.cameras[view]

            ref = expose(desc, view, RenderConfig(spp=args.ref_spp), variant)
            exposures = {}
            for spp in sorted({s for s, _ in levers} | {base.spp}):
                t = time.perf_counter()
                exposures[spp] = (expose(desc, view, RenderConfig(spp=spp), variant), 0.0)
                exposures[spp] = (exposures[spp][0], time.perf_counter() - t)
            cases = [(spp, d, DetectorConfig.sift_contrast) for spp, d in levers]
            cases += [(base.spp, 0.0, c) for c in contrasts]
            for spp, strength, contrast in cases:
                (rgb, albedo, _, _), render_s = exposures[spp]
                t = time.perf_counter()
                image = develop(rgb, albedo, strength)
                develop_s = time.perf_counter() - t
                xy = pool(image, camera, contrast)
                ref_xy = pool(develop(ref[0], ref[1], strength), camera, contrast)
                name = f"{spp} spp" + (f", denoise {strength:g}" if strength else "")
                if contrast != DetectorConfig.sift_contrast:
                    name += f", contrast {contrast:g}"
                rows.append(
                    {
                        "scene": scene,
                        "view": view,
                        "setting": name,
                        "spp": spp,
                        "denoise": strength,
                        "contrast": contrast,
                        "candidates_per_mp": len(xy) / (camera.width * camera.height / 1e6),
                        "noise_pct": 100.0 * float((~near(xy, ref_xy)).mean()) if len(xy) else 0.0,
                        "kept_pct": 100.0 * float(near(ref_xy, xy).mean()) if len(ref_xy) else 0.0,
                        "render_s": render_s,
                        "develop_s": develop_s,
                    }
                )
                print(rows[-1], flush=True)
                if args.out:
                    pd.DataFrame(rows).to_csv(args.out, index=False)
    table = pd.DataFrame(rows).groupby(["setting", "scene"], sort=False).mean(numeric_only=True)
    print(table.drop(columns="view").to_string(float_format="%.3g"))


if __name__ == "__main__":
    main()
