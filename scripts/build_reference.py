"""Rebuild the reference renders (`reference/`, `bench.render.reference`): every rig of both
regimes rendered (or found in the render cache) with the default settings, then each view
written once as lossless WebP under the SHA-256 manifest.

    .venv/bin/python scripts/build_reference.py [RENDERS_DIR] [--variant V]

Only after a scene or the render code changed: the set is data, committed once per change
(docs/scenes.md, "The reference renders"). Rendering both regimes takes about 20 minutes
on 2 cores with the LLVM variant.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bench import ROOT
from bench.cli.common import REGIMES, parse_list
from bench.render.config import RenderConfig
from bench.render.entry import reference_input, render_scene
from bench.render.reference import REFERENCE, write_reference
from bench.scenes.catalog import scene_names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("renders", nargs="?", type=Path, default=ROOT / "renders")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant named")
    args = parser.parse_args()
    entries = [
        render_scene(scene, seed, RenderConfig(views=views, variant=args.variant), args.renders)
        for views, seeds in REGIMES.values()
        for seed in parse_list("--seeds", seeds, int)
        for scene in scene_names()
    ]
    manifest = write_reference([reference_input(e) for e in entries])
    size = sum((REFERENCE / n).stat().st_size for n in manifest["images"])
    print(
        f"{REFERENCE}: {len(manifest['rigs'])} rigs, {len(manifest['images'])} images, "
        f"{size / 1e6:.1f} MB"
    )


if __name__ == "__main__":
    main()
