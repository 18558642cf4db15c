"""The own-image question (issue 53), the renders' side: the renders are drawn with a box
pixel filter and no optics, so their finest detail is sharper than a camera's, whose lens
and sensor (optical low-pass filter, demosaicing) blur every image by a point spread
function of about a pixel. This exports render entries as datasets (their poses as the
truth) twice: as rendered, and with a Gaussian blur of `--sigma` px applied to every
developed image, a stand-in for that point spread function; `bench run --dataset` then
scores the same methods on both. Images only change; nothing is re-rendered.

    PYTHONPATH=. .venv/bin/python benchmarks/own_image_blur.py --renders /tmp/h53/renders \
        --scenes corridor-s0,facade-s0 --sigma 0.7 --out /tmp/h53/blur
    bench run --dataset /tmp/h53/blur/sharp --dataset ... (see docs/protocol.md)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2

from bench.evaluation.export import export_dataset


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--renders", type=Path, required=True)
    ap.add_argument("--scenes", required=True, help="entry name prefixes: corridor-s0,...")
    ap.add_argument("--sigma", type=float, default=0.7)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    for prefix in args.scenes.split(","):
        entries = sorted(args.renders.glob(f"{prefix}-*"))
        if len(entries) != 1:
            print(f"own_image_blur: {len(entries)} entries match {prefix}", file=sys.stderr)
            return 2
        for kind in ("sharp", "blurred"):
            out = export_dataset(entries[0], args.out / kind / prefix)
            if kind == "blurred":
                for image in sorted((out / "images").iterdir()):
                    picture = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
                    blurred = cv2.GaussianBlur(picture, (0, 0), args.sigma)
                    cv2.imwrite(str(image), blurred)
    return 0


if __name__ == "__main__":
    sys.exit(main())
