"""`bench select`: B keypoints per image of your own photographs, into a COLMAP database."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from bench import BenchError
from bench.cli.common import settings_arg

HELP = "select B keypoints per image of your own photographs into a COLMAP database"
DESCRIPTION = (
    "Detect the candidate pool on every image in DIR (JPEG, PNG, TIFF, WebP; two or more, "
    "any size; other files are named and skipped), compute the signals the policy reads, "
    "select B per image with POLICY and write OUT/database.db: cameras, images, the "
    "selected keypoints and their SIFT descriptors in COLMAP's format (COLMAP's matchers "
    "and mapper accept it). The front end is `bench run`'s, with its settings (--set): "
    "images larger than detector.max_image_size are detected downscaled. Calibration from "
    "--cameras (a COLMAP model with poses) or else one camera per image size from the "
    "focal-length prior (EXIF 35 mm equivalent; without it the focal length is guessed, "
    "estimated from the images and written as an untrusted prior); without poses the "
    "geometry the signals need is estimated from the images, like the sfm task's."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--images", type=Path, required=True, metavar="DIR", help="image folder")
    parser.add_argument(
        "--policy", default="adaptive", help="selection policy (default: %(default)s)"
    )
    parser.add_argument(
        "--budget", type=int, default=1024, help="keypoints per image (default: %(default)s)"
    )
    parser.add_argument("--out", type=Path, required=True, metavar="OUT", help="output folder")
    parser.add_argument(
        "--cameras",
        type=Path,
        default=None,
        metavar="MODEL",
        help="a model giving intrinsics and poses: a folder with COLMAP's cameras and images "
        "(.txt or .bin), or a model of another registered format",
    )
    parser.add_argument(
        "--match",
        action="store_true",
        help="also write the matches and verified two-view geometries (colmap mapper runs on "
        "the database directly)",
    )
    parser.add_argument(
        "--overlays", action="store_true", help="write OUT/overlays/<image>.png of each selection"
    )
    parser.add_argument(
        "--max-candidates",
        type=int,
        default=None,
        help="candidate pool per image: the strongest detections; the setting "
        "detector.max_features (default: 8192)",
    )
    parser.add_argument(
        "--policy-module", action="append", default=[], metavar="FILE", help="as for `bench run`"
    )
    settings_arg(
        parser,
        "a setting of the detector, signals, policy or back end, as for `bench run` "
        "(repeatable; e.g. --set detector.max_image_size=2000)",
    )


def run(args: argparse.Namespace) -> None:
    from bench.cli.common import apply_settings
    from bench.harness.select import SelectRequest, select_to_database
    from bench.unit.config import RunConfig

    if args.budget <= 0 or (args.max_candidates is not None and args.max_candidates <= 0):
        raise BenchError("--budget and --max-candidates must be positive")
    cfg = RunConfig(render=None)
    cfg = replace(cfg, policy=replace(cfg.policy, modules=tuple(args.policy_module)))
    if args.max_candidates is not None:
        cfg = replace(cfg, detector=replace(cfg.detector, max_features=args.max_candidates))
    request = SelectRequest(
        images=args.images,
        policy=args.policy,
        budget=args.budget,
        cameras=args.cameras,
        match=args.match,
        overlays=args.overlays,
        settings=apply_settings(cfg, args.settings),
    )
    print(select_to_database(request, args.out))
