"""`bench select` timing per image: the six views of a default render at 640x480, and the
same views upscaled to 4000x3000 (12 megapixels), without poses, policy adaptive.

    .venv/bin/python benchmarks/select_speed.py [--scene table] [--budget 1024]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2

from bench import ROOT
from bench.backend.database import SelectRequest, select_to_database
from bench.frontend.views import Source, read_colmap_model
from bench.render.config import RenderConfig
from bench.render.entry import render_scene


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="table")
    ap.add_argument("--budget", type=int, default=1024)
    ap.add_argument("--policy", default="adaptive")
    a = ap.parse_args()
    entry = render_scene(a.scene, 0, RenderConfig(), ROOT / "renders")
    names = [n for n, _ in read_colmap_model(Source.of(entry).model)]
    with tempfile.TemporaryDirectory() as tmp:
        for size in ((640, 480), (4000, 3000)):
            folder = Path(tmp) / f"{size[0]}x{size[1]}"
            folder.mkdir()
            for n in names:
                img = cv2.imread(str(entry / n))
                cv2.imwrite(
                    str(folder / f"{Path(n).stem}.jpg"),
                    cv2.resize(img, size, interpolation=cv2.INTER_CUBIC),
                    [cv2.IMWRITE_JPEG_QUALITY, 95],
                )
            t = time.perf_counter()
            select_to_database(
                SelectRequest(folder, a.policy, a.budget), Path(tmp) / f"out-{size[0]}"
            )
            s = (time.perf_counter() - t) / len(names)
            print(
                f"{size[0]}x{size[1]}: {s:.2f} s per image ({len(names)} images, {a.policy}, B={a.budget})"
            )


if __name__ == "__main__":
    main()
