"""`bench frontend`: the front end alone, on a folder of images, a dataset or a render
entry, into the cache `bench run` reads it from."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bench import BenchError
from bench.cli.common import folder, settings_arg

HELP = "detect the candidates and compute the signals of every image of a folder, cached"
DESCRIPTION = (
    "The front end alone: detect the candidate pool of every image of DIR and compute its "
    "signals, as `bench run` does (its settings: --detector, --set), and write them to "
    "OUT/<folder>-<detector>-<geometry>-<key>.npz (per view V: the candidates' xy_V, "
    "size_V, angle_V, response_V and descriptors_V, each signal's <signal>_V, and the "
    "seconds measured), the file `bench run` caches them in "
    "(RENDERS/frontend/; the key hashes the images and the model, the settings, the "
    "geometry and the front end's code), then print its path; a file already there is "
    "read, not computed again. DIR is a folder of images (JPEG, PNG, TIFF, WebP; two or "
    "more; other files are named and skipped; no poses: the focal-length prior as `bench "
    "select` has it), a dataset (DIR/images/ and a model that poses them: a COLMAP model "
    "in DIR/sparse/0/ or DIR/sparse/, or another registered format) or a render entry. "
    "With --out RENDERS/frontend, `bench run --dataset DIR --bag-size 0 --renders RENDERS` "
    "reads what it wrote (a run in bags caches a part of its own for its bags)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from bench.frontend.geometry import IMAGES, RIG
    from bench.frontend.pools import POOLS

    parser.add_argument(
        "--images",
        type=Path,
        required=True,
        metavar="DIR",
        help="a folder of images, a dataset (images/ and a model) or a render entry",
    )
    parser.add_argument(
        "--out",
        type=folder,
        required=True,
        metavar="OUT",
        help="the cache folder (bench run's: RENDERS/frontend/, --renders' frontend/)",
    )
    parser.add_argument(
        "--detector",
        default="sift",
        metavar="POOL",
        help=f"the candidate pool: {', '.join(POOLS)} (default: %(default)s)",
    )
    parser.add_argument(
        "--geometry",
        choices=(RIG, IMAGES),
        default=None,
        help=f"the geometry the signals read: {RIG} (the model's poses, as the tri task "
        f"grants them) or {IMAGES} (estimated from the images, as the sfm task's); "
        f"default: {RIG} where DIR has a model, else {IMAGES}",
    )
    settings_arg(
        parser,
        "a setting of the detector or the signals, as for `bench run` (repeatable; e.g. "
        "--set detector.max_image_size=2000)",
    )


def run(args: argparse.Namespace) -> None:
    from bench.cli.common import apply_settings
    from bench.console import log
    from bench.frontend.features import DetectorConfig
    from bench.frontend.formats import layouts
    from bench.frontend.geometry import IMAGES, RIG
    from bench.frontend.stage import cache_file, front_end
    from bench.frontend.views import images_alone, load_image_folder, load_views
    from bench.unit.config import RunConfig

    cfg = RunConfig(render=None, detector=DetectorConfig(detector=args.detector))
    cfg = apply_settings(cfg, args.settings).validate()
    images = args.images.resolve()
    alone = images_alone(images)
    grant = args.geometry or (IMAGES if alone else RIG)
    if grant == RIG and alone:
        raise BenchError(
            f"--geometry {RIG} needs the views' poses, and {images} is a folder of images "
            f"alone: give a dataset (images/ and {layouts()}), or --geometry {IMAGES}"
        )
    views = load_image_folder(images) if alone else load_views(images)
    t = time.perf_counter()
    fe = front_end(images, cfg.detector, cfg.signals, args.out, grant, views)
    how = "read from the cache" if fe.cached else f"computed in {time.perf_counter() - t:.1f} s"
    count = sum(len(p) for p in fe.pools)
    log(f"{len(views)} views, {count} candidates ({args.detector}, geometry {grant}): {how}")
    print(cache_file(images, cfg.detector, cfg.signals, args.out, grant))
