"""How like photographs the renders are (issue 28, point 1): the same four measures for
rendered scenes and for datasets of photographs, one row per image set.

    .venv/bin/python benchmarks/realism.py --scenes corridor,facade,table,vegetation \
        --dataset ../shared/datasets/middlebury-temple-sparse [--dataset ...] \
        [--rendered-results results/published] [--dataset-results results/datasets] \
        [--ref-spp 512] [--ref-views 1] [--renders renders]

Measures (each at the working size the front end detects at, `detector.max_image_size`):

- `candidates_per_mp`: SIFT candidates (the pool's detector, uncapped) per megapixel.
- `strong_pct`: the share of those candidates whose response reaches OpenCV's default
  SIFT contrast threshold (0.04 / 3; the pool detects down to 0.005 / 3): a surplus of
  candidates made of weak ones shows here.
- `dog_kurtosis`: the excess kurtosis of the finest difference of Gaussians (sigma 1.6 and
  2.0) over the image: band-pass responses of photographs are sparse (a few strong edges,
  much flat area: heavy-tailed, well above 0), texture spread evenly over the image is not.
- `textured_pct`: the share of pixels with texture at SIFT's scales: where the largest
  absolute difference of Gaussians over two octaves (sigma 1.6 * 2^(k/3), k = 0..6, on
  the grey image in [0, 1]) reaches OpenCV's default SIFT contrast threshold per scale
  (0.04 / 3). Flat walls, sky and blurred backgrounds are not textured.
- `noise_unrepeatable_pct` (renders only): the share of candidates at the default spp
  with no candidate within 1 px in the same view rendered at `--ref-spp` (the first
  `--ref-views` views): candidates made by render noise, which a photograph does not have;
  `candidates_per_mp_ref` is `candidates_per_mp` of those views at `--ref-spp`.
- `verified_per_pair_<policy>`: verified matches per pair of views at B = 256 in the sfm
  task (multiview protocol), mean over the rows of a results folder's `runs.csv`
  (`--rendered-results` for scenes, `--dataset-results` for datasets); all pairs count.
"""

from __future__ import annotations

import argparse
from math import comb
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree
from scipy.stats import kurtosis

from bench.frontend.features import DetectorConfig, detect
from bench.frontend.views import View, load_views
from bench.render.config import RenderConfig
from bench.render.entry import render_scene
from bench.render.mitsuba import render_view
from bench.render.variant import resolve_variant
from bench.scenes.catalog import build_scene, load_spec

UNCAPPED = DetectorConfig(max_features=10**7)
SIGMAS = 1.6 * 2.0 ** (np.arange(7) / 3)
CONTRAST = 0.04 / 3
POLICIES = ("response", "texture")


def working(view: View) -> View:
    """The view at the size the front end detects at."""
    return view.scale_to(DetectorConfig.max_image_size)[0]


def textured_pct(gray: np.ndarray) -> float:
    g = gray.astype(np.float32) / 255.0
    blurred = [cv2.GaussianBlur(g, (0, 0), s) for s in SIGMAS]
    dog = np.max([np.abs(b - a) for a, b in zip(blurred, blurred[1:])], axis=0)
    return 100.0 * float((dog >= CONTRAST).mean())


def dog_kurtosis(gray: np.ndarray) -> float:
    g = gray.astype(np.float32) / 255.0
    dog = cv2.GaussianBlur(g, (0, 0), SIGMAS[1]) - cv2.GaussianBlur(g, (0, 0), SIGMAS[0])
    return float(kurtosis(dog.ravel()))


def image_measures(views: list[View]) -> dict:
    views = [working(v) for v in views]
    mp = [v.camera.width * v.camera.height / 1e6 for v in views]
    responses = [detect(v, UNCAPPED).response for v in views]
    return {
        "views": len(views),
        "size": f"{views[0].camera.width}x{views[0].camera.height}",
        "candidates_per_mp": float(np.mean(np.divide([len(r) for r in responses], mp))),
        "strong_pct": float(np.mean([100.0 * np.mean(r >= CONTRAST) for r in responses])),
        "dog_kurtosis": float(np.mean([dog_kurtosis(v.gray) for v in views])),
        "textured_pct": float(np.mean([textured_pct(v.gray) for v in views])),
    }


def reference_measures(
    scene: str, seed: int, views: list[View], ref_spp: int, ref_views: int, renders: Path
) -> dict:
    """The share of the default render's candidates with no candidate within 1 px at
    `ref_spp`, and the candidates per megapixel at `ref_spp` (with little render noise)."""
    cfg = RenderConfig(spp=ref_spp)
    variant, _ = resolve_variant(cfg.variant, renders)
    desc = build_scene(load_spec(scene), seed, cfg.width, cfg.height, cfg.views)
    lost, total, ref_total = 0, 0, 0
    for v in range(ref_views):
        image, _, _ = render_view(desc, v, cfg, variant)
        ref = working(View(v, "ref", image, views[v].camera))
        a, b = detect(working(views[v]), UNCAPPED).xy, detect(ref, UNCAPPED).xy
        d, _ = cKDTree(b).query(a, distance_upper_bound=1.0)
        lost, total, ref_total = lost + int(np.isinf(d).sum()), total + len(a), ref_total + len(b)
    mp = ref.camera.width * ref.camera.height / 1e6
    return {
        "noise_unrepeatable_pct": 100.0 * lost / max(total, 1),
        "candidates_per_mp_ref": ref_total / ref_views / mp,
    }


def verified_per_pair(results: Path | None, scene: str) -> dict:
    if results is None or not (results / "runs.csv").is_file():
        return {}
    runs = pd.read_csv(results / "runs.csv")
    at = runs[
        (runs["scene"] == scene)
        & (runs["budget"] == 256)
        & (runs["task"] == "sfm")
        & (runs["protocol"] == "multiview")
    ]
    out = {}
    for p in POLICIES:
        rows = at[at["method"] == p]
        pairs = rows["views"].map(lambda n: comb(int(n), 2))
        out[f"verified_per_pair_{p}"] = float((rows["verified_matches"] / pairs).mean())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="corridor,facade,table,vegetation")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dataset", type=Path, action="append", default=[])
    ap.add_argument("--rendered-results", type=Path, default=Path("results/published"))
    ap.add_argument("--dataset-results", type=Path, default=None)
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--ref-views", type=int, default=1)
    ap.add_argument("--renders", type=Path, default=Path("renders"))
    args = ap.parse_args()
    rows = []
    for scene in [s for s in args.scenes.split(",") if s]:
        entry = render_scene(scene, args.seed, RenderConfig(), args.renders)
        views = load_views(entry)
        row = {"set": f"{scene} s{args.seed}", **image_measures(views)}
        row |= reference_measures(
            scene, args.seed, views, args.ref_spp, args.ref_views, args.renders
        )
        rows.append(row | verified_per_pair(args.rendered_results, scene))
        print(rows[-1], flush=True)
    for ds in args.dataset:
        row = {"set": ds.name, **image_measures(load_views(ds))}
        rows.append(row | verified_per_pair(args.dataset_results, ds.name))
        print(rows[-1], flush=True)
    print(pd.DataFrame(rows).to_string(index=False, float_format="%.3g"))


if __name__ == "__main__":
    main()
