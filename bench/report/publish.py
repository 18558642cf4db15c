"""`bench publish`: a checked results folder copied into a snapshot the repository tracks
(its rows, settings, manifest, tables and figures; its page written from what it holds)."""

from __future__ import annotations

import shutil
from pathlib import Path

from bench import BenchError
from bench.binding import read_settings
from bench.failures import errors
from bench.files import atomic_path, write_text_atomic
from bench.report.page import results_page
from bench.results import (
    CONFIG,
    FIGURE2,
    FIGURE3,
    FIGURE_BUDGET,
    FIGURE_COST,
    FIGURE_TRANSFER,
    FIGURE_VIEWS,
    GALLERY,
    MANIFEST,
    PAGE,
    RUNS,
    TABLE1,
    TABLE1_EQUAL,
    TABLE_COST,
    TABLE_POOLS,
    TABLES,
    TRANSFER,
    TRANSFER_RANKS,
    VERDICTS,
    VOCABULARY,
    png,
    table1_of,
)
from bench.runs import NO_PIXELS, pixels_of, read_runs

PUBLISHED_FILES = (RUNS, CONFIG, VOCABULARY, MANIFEST, GALLERY, *TABLES, TABLE1_EQUAL, VERDICTS)
PUBLISHED_FILES += (TABLE_COST, TABLE_POOLS, TRANSFER, TRANSFER_RANKS)
FIGURE_FILES = (*map(png, (FIGURE2, FIGURE3, FIGURE_BUDGET, FIGURE_VIEWS)), f"{FIGURE3}.pdf")
FIGURE_FILES += (png(FIGURE_COST), png(FIGURE_TRANSFER))
PER_DATASET = table1_of("*")
"""A photo run's Table 1 of each of its datasets: published with it, as its transfer."""


def check_publishable(results: Path, regime: dict | None = None) -> None:
    """Refuse in one line a results folder unfit to publish: damaged rows (`read_runs`),
    rows that could not be computed (`error: `), rows that name no pixels, no Table 1 or page (`bench plot` writes
    them) and, given a `regime` (its `name`, `scenes`, `seeds`, `views`, `width` and
    `height`), a grid or render size that is not that regime's."""
    results = Path(results)
    rows = read_runs(results / RUNS)
    if errors(rows):
        raise BenchError(
            f"{results} is not published: {errors(rows)}; fix what raised (a policy module "
            "that broke its contract, say) and the same `bench run` computes them again"
        )
    unnamed = int((pixels_of(rows) == NO_PIXELS).sum())
    if unnamed:
        raise BenchError(
            f"{results} is not published: {unnamed} row(s) name no pixels (written before rows "
            "recorded the images they read); the same `bench run` again computes them"
        )
    missing = [n for n in (TABLE1, PAGE) if not (results / n).is_file()]
    if missing:
        raise BenchError(
            f"{results} has no {' or '.join(missing)}: `bench plot --results {results}` "
            "writes its tables and page (Table 1 from the rows of the multiview protocol)"
        )
    if regime is None:
        return
    render = read_settings(results)["render"]
    if render is None:
        differ = ["a dataset run, not a render"]
    else:
        here = {
            "scenes": sorted(set(rows["scene"])),
            "seeds": sorted(int(s) for s in set(rows["seed"])),
            "views": render["views"],
            "render size": f"{render['width']}x{render['height']}",
        }
        wanted = {k: regime[k] for k in ("scenes", "seeds", "views")}
        wanted["render size"] = f"{regime['width']}x{regime['height']}"
        show = lambda v: ", ".join(map(str, v)) if isinstance(v, list) else v  # noqa: E731
        differ = [
            f"{k} {show(here[k])}, the regime's {show(v)}"
            for k, v in wanted.items()
            if here[k] != v
        ]
    if differ:
        raise BenchError(
            f"{results} is not the {regime['name']} regime's grid ({'; '.join(differ)}); "
            f"publish a `bench run --regime {regime['name']}` there, or this folder "
            "elsewhere with --to DIR and no --regime"
        )


def publish(results: Path, to: Path, regime: dict | None = None) -> int:
    """Copy a results folder's rows, settings, manifest, tables and figures into the
    snapshot `to`, after checking it (`check_publishable`: nothing is created where it is
    refused); report files `results` lacks are removed from `to`, so the snapshot never
    mixes runs; its page is written from what it holds (under its own name). How many
    files were copied or written."""
    check_publishable(results, regime)
    to.mkdir(parents=True, exist_ok=True)
    copied = 0
    per_dataset = {p.name for d in (results, to) for p in Path(d).glob(PER_DATASET)}
    for name in (*PUBLISHED_FILES, *FIGURE_FILES, *sorted(per_dataset)):
        src, dst = Path(results) / name, to / name
        if src.is_file():
            with atomic_path(dst) as tmp:
                shutil.copyfile(src, tmp)
            copied += 1
        elif name != GALLERY:
            dst.unlink(missing_ok=True)
    write_text_atomic(to / PAGE, results_page(to))
    return copied + 1
