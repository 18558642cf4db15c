"""`bench select`: B keypoints per image of your own photographs, into a COLMAP database."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench import BenchError

HELP = "select B keypoints per image of your own photographs into a COLMAP database"
DESCRIPTION = (
    "Detect the candidate pool on every JPEG/PNG image in DIR (two or more, any size), "
    "compute the signals, select B per image with POLICY and write OUT/database.db: "
    "cameras, images, the selected keypoints and their SIFT descriptors in COLMAP's format "
    "(COLMAP's matchers and mapper accept it). Calibration from --cameras (a COLMAP model "
    "with poses) or else one camera per image size from the focal-length prior (EXIF 35 mm "
    "equivalent, else 1.2 x max(width, height)); without poses the geometry the signals "
    "need is estimated from the images, like the sfm task's."
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
        help="COLMAP text model (folder with cameras.txt and images.txt) giving intrinsics and "
        "poses",
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
        default=8192,
        help="candidate pool per image: the strongest detections (default: %(default)s)",
    )
    parser.add_argument(
        "--policy-module", action="append", default=[], metavar="FILE", help="as for `bench run`"
    )


def run(args: argparse.Namespace) -> None:
    from bench.backend.database import SelectRequest, select_to_database

    if args.budget <= 0 or args.max_candidates <= 0:
        raise BenchError("--budget and --max-candidates must be positive")
    request = SelectRequest(
        images=args.images,
        policy=args.policy,
        budget=args.budget,
        cameras=args.cameras,
        match=args.match,
        overlays=args.overlays,
        policy_modules=tuple(args.policy_module),
        max_candidates=args.max_candidates,
    )
    print(select_to_database(request, args.out))
