"""`bench publish`: a checked results folder into the snapshot the repository tracks."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.cli.common import (
    LATEST,
    NBV,
    PHOTOS,
    POOLS_PHOTOS,
    POOLS_RUN,
    PUBLISHED,
    REGIMES,
    folder,
    parse_list,
    regime_arg,
    regime_folder,
    results_arg,
)
from bench.results import PAGE

README = Path(PAGE)
"""The repository's README (a results page's name), relative to the current directory (the
repository root)."""

HELP = "copy a results folder's runs, tables and figures into the published snapshot"
DESCRIPTION = (
    "Check RESULTS/runs.csv row by row (no damaged row, none that could not be computed) "
    "and that `bench plot` wrote its tables, then copy it with config.json, "
    "vocabulary.json, manifest.json, the tables and the figures into TO (the snapshot the "
    "repository tracks), removing report files there that RESULTS does not have. With "
    "--regime, or into the regime's snapshot (no --to), RESULTS must hold the regime's "
    "grid: every scene, its seeds and views, the default render size. A snapshot of other "
    "settings (config.json) or another grid (scenes, seeds, methods, budgets, tasks, "
    "protocols) is replaced only with --replace. A refused publish creates nothing. Its "
    "origin.json records what made the rows (commit, code and module hashes, each (method, "
    "task)'s protocol, the reference renders: what `bench verdict` judges by), written "
    "only where every row was computed by this checkout's code (else it says why not)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    dense = regime_folder(LATEST, "dense"), regime_folder(PUBLISHED, "dense")
    results_arg(parser, None, f"results folder to publish (default: ./{LATEST}, or ./{dense[0]})")
    parser.add_argument(
        "--to",
        type=folder,
        default=None,
        help=f"snapshot folder (default: ./{PUBLISHED}, or ./{dense[1]})",
    )
    regime_arg(parser, "sets the default --results and --to")
    parser.add_argument(
        "--replace",
        action="store_true",
        help="replace a snapshot of other settings or another grid (refused without it)",
    )
    parser.add_argument(
        "--readme",
        action="store_true",
        help="only rewrite ./README.md's results section (between its markers) from the "
        f"published snapshots, ./{PUBLISHED} and ./{dense[1]}, the photo sets' "
        f"./{regime_folder(PUBLISHED, PHOTOS)}, the next views' "
        f"./{regime_folder(PUBLISHED, NBV)} and the cross-pool ones, "
        f"./{regime_folder(PUBLISHED, POOLS_RUN)} (renders) and "
        f"./{regime_folder(PUBLISHED, POOLS_PHOTOS)} (photo sets); publishing into one of "
        "them rewrites it too",
    )


def _defaults() -> dict:
    """The settings' defaults (imports OpenCV and COLMAP: only where a setting is missing)."""
    from bench.unit.config import RunConfig

    return RunConfig().as_dict()


def regime_grid(name: str) -> dict:
    """What a regime's results folder holds: every scene, the regime's seeds and views, and
    the default render size."""
    from bench.render.config import RenderConfig
    from bench.scenes.spec import scene_names

    views, seeds = REGIMES[name]
    render = RenderConfig()
    return {
        "name": name,
        "scenes": scene_names(),
        "seeds": list(parse_list("--seeds", seeds, int)),
        "views": views,
        "width": render.width,
        "height": render.height,
    }


def write_readme(readme: Path = README, required: bool = True) -> None:
    """Rewrite `readme`'s results section from the published snapshots beside it
    (`bench.report.summary`); not `required` (after a publish): only a README with the
    section's markers."""
    from bench import BenchError
    from bench.files import write_text_atomic
    from bench.report.summary import BEGIN, with_section

    if not required and not (readme.is_file() and BEGIN in readme.read_text()):
        return
    if not readme.is_file():
        raise BenchError(f"{readme} not found: run bench publish --readme in the repository root")
    text = with_section(readme.read_text(), readme_section(readme.parent / PUBLISHED))
    if text != readme.read_text():
        write_text_atomic(readme, text)
        print(f"{readme}: results section rewritten from the snapshots in {PUBLISHED.parent}")


def readme_section(base: Path = PUBLISHED) -> str:
    """The README's results section from the regimes' snapshots (`base` the sparse one's
    folder), the photo sets' and the next views' (`bench.report.summary`)."""
    from bench.report.summary import PHOTO_ROWS, results_section

    snapshots = {r: regime_folder(base, r) for r in REGIMES}
    photos, nbv = regime_folder(base, PHOTOS), regime_folder(base, NBV)
    pools = {
        "renders": regime_folder(base, POOLS_RUN),
        PHOTO_ROWS: regime_folder(base, POOLS_PHOTOS),
    }
    return results_section(snapshots, photos, nbv, pools)


def _origin(results: Path) -> tuple[dict | None, str]:
    """The origin of the snapshot `results` makes, its rows checked against this
    checkout's code (`bench.harness.origin`); or None and why there is none."""
    from bench import BenchError

    try:
        from bench.cli.common import folder_origin
        from bench.harness.manifest import git_commit

        return folder_origin(results, git_commit(), Path.read_text), ""
    except ImportError as e:  # the report's commands run without the pipeline's libraries
        return None, f"{e.name} is not installed"
    except BenchError as e:
        return None, str(e)


def run(args: argparse.Namespace) -> None:
    from bench import BenchError
    from bench.binding import snapshot_differences
    from bench.console import log
    from bench.report.publish import check_publishable, publish
    from bench.results import ORIGIN, RUNS, holding
    from bench.runs import runs_file

    if args.readme:
        write_readme()
        return
    regime = args.regime or "sparse"
    # named, or its snapshot the target: the folder must hold that regime's grid
    grid = regime_grid(regime) if args.regime or args.to is None else None
    args.results = args.results or regime_folder(LATEST, regime)
    args.to = args.to or regime_folder(PUBLISHED, regime)
    runs_file(args.results / RUNS)
    with holding(args.results, reading=True):
        check_publishable(args.results, grid)  # before anything is created
    try:
        args.to.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(f"cannot write to {args.to}: {e.strerror}") from None
    with holding(args.results, reading=True), holding(args.to):
        differ = [] if args.replace else snapshot_differences(args.results, args.to, _defaults)
        if differ:
            raise BenchError(
                f"{args.to} holds a snapshot of other settings or another grid "
                f"({'; '.join(differ)}); --replace replaces it"
            )
        origin, why = _origin(args.results)
        n = publish(args.results, args.to)
        if origin is not None:  # the pipeline's libraries are there: its module imports
            from bench.harness.origin import write_origin

            write_origin(args.to, origin)
        else:
            (args.to / ORIGIN).unlink(missing_ok=True)
            log(
                f"no {ORIGIN} recorded ({why}): `bench verdict` judges only against a "
                "snapshot whose rows this checkout's code computed"
            )
    if grid is None:  # a snapshot of its own, said (its grid may be a --quick run's)
        log(
            f"published as a snapshot of its own: {args.results}'s grid is checked against "
            "a regime's only with --regime sparse|dense"
        )
    print(f"published {n} files of {args.results} in {args.to}")
    if args.to.resolve() in {
        regime_folder(PUBLISHED, r).resolve()
        for r in (*REGIMES, PHOTOS, NBV, POOLS_RUN, POOLS_PHOTOS)
    }:
        write_readme(required=False)
