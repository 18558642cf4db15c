"""The focal length `bench select` estimates for photographs without one (no EXIF, no
model), against the truth of COLMAP-layout datasets: per dataset, windows of 3, 4 and 8
consecutive images (from the first and from the middle one) and all of them, each copied
without its model (and without EXIF) into a temporary folder and read as `bench select`
reads it. Prints one row per subset: the estimate, or the prior it falls back to
(1.2 x max(width, height)) and why, against the model's focal length, with the pairs it
rests on and the support of the rule (`bench.frontend.geometry.FOCAL_PEAK`): the matches
the relative poses explain at the estimate and at most at 1.5 times or 1/1.5 of it.

    .venv/bin/python benchmarks/focal_estimate.py ../shared/datasets/middlebury-temple-sparse \\
        ../shared/datasets/middlebury-dino-sparse ../shared/datasets/strecha-herzjesu-p8
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import cv2

from bench.frontend.colmap_model import find_model, read_model
from bench.frontend.features import DetectorConfig, detect
from bench.frontend.geometry import SignalConfig, estimate_focal
from bench.frontend.views import DEFAULT_FOCAL_FACTOR, exif_focal, load_image_folder


def subsets(names: list[str]) -> list[list[str]]:
    """Windows of 3, 4 and 8 consecutive images from the first and the middle one, and all."""
    n = len(names)
    out = [[names[(s + m) % n] for m in range(k)] for k in (3, 4, 8) if k < n for s in (0, n // 2)]
    return out + [names]


def copy_without_model(images: Path, names: list[str], folder: Path) -> None:
    """The images alone, as a user's folder holds them (EXIF dropped where there is any)."""
    for name in names:
        src = images / name
        img = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
        if exif_focal(src, img.shape[1], img.shape[0]) is None:
            shutil.copy(src, folder / name)
        else:
            cv2.imwrite(str(folder / name), img, [cv2.IMWRITE_JPEG_QUALITY, 100])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path, help="datasets in the COLMAP layout")
    a = ap.parse_args()
    det, sig = DetectorConfig(), SignalConfig()
    print(
        "| set | images | estimate | truth | error % | fallback | pairs | matches explained "
        "at the estimate / 1.5x off | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for ds in a.datasets:
        model = read_model(find_model(ds))
        size = max(model[0][1].width, model[0][1].height)
        truth = model[0][1].fx
        names = sorted(n for n, _ in model)
        for sub in subsets(names):
            with tempfile.TemporaryDirectory(prefix="focal-") as tmp:
                copy_without_model(ds / "images", sub, Path(tmp))
                views = load_image_folder(Path(tmp))
                work = [v.scale_to(det.max_image_size)[0] for v in views]
                t = time.perf_counter()
                found = estimate_focal(work, [detect(v, det) for v in work], sig)
                seconds = time.perf_counter() - t
            f = (found.factor or DEFAULT_FOCAL_FACTOR) * size
            what = f"{f:.0f} px" + ("" if found.factor else " (the prior)")
            best, off = found.explained
            fallback = "no" if found.factor else f"yes: {'not determined' if off else found.why}"
            ratio = f"{best} / {off} = {best / off:.2f}" if off else "-"
            print(
                f"| {ds.name} | {len(sub)} ({sub[0]}-{sub[-1]}) | {what} | {truth:.0f} px | "
                f"{100 * (f / truth - 1):+.0f} | {fallback} | {found.pairs} | {ratio} | "
                f"{seconds:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
