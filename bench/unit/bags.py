"""Bags: a dataset scored on random co-visible subsets of its images, as the Image Matching
Challenge scores a scene (docs/protocol.md, "Verdicts and their power").

Bag k of a dataset is drawn by a generator seeded with k (`draw_bags`): a first image at
random, then one at a time an image drawn at random among those co-visible with an image
already in the bag, until the bag's size; a draw that repeats an earlier bag is drawn
again (`REDRAWS` times at most; the bags are then fewer). Co-visibility is the `pairs`
task's, from the dataset's model alone: at least `MIN_SHARED` common model points, else
viewing directions within `COVISIBLE_DEG` with overlapping frustums. A dataset with no
more images than the bag's size is one bag of all of them.

A bag is a scene of its own to the units that read it: its views, their candidates (the
dataset's, detected once per image and cached), the signals computed on the bag's views
alone (`bench.frontend.stage.bag_front_end`: those that read other views see only the
bag's), and the ground truth of its views (`bag_truth`). The bag is a field of its units
(`Unit.bag`: its image names, space-separated), so of its rows' key (column
`bench.vocabulary.BAG`, part of `KEY`; `views`: its size): a row of another bag is another
row.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.evaluation.relative import MIN_SHARED
from bench.evaluation.truth import COVISIBLE_DEG, covisible_pairs, scene_truth
from bench.frontend.geometry import RIG
from bench.frontend.stage import FrontEnd
from bench.frontend.views import Source, load_views

REDRAWS = 100
"""The draws of one bag that may repeat an earlier bag before the bags stop."""
DEFAULT_SIZE, DEFAULT_COUNT = 6, 10
"""The default bag: the sparse regime's 6 views, 10 bags (docs/protocol.md)."""


def draw_bags(n: int, links, size: int, count: int) -> list[tuple[int, ...]]:
    """`count` distinct bags of `size` of the views 0..n-1, each grown at random along the
    co-visibility `links` (pairs of views) by a generator seeded with its number (module
    docstring); one bag of every view where `size` >= n (or `size` is 0)."""
    if size <= 0 or size >= n:
        return [tuple(range(n))]
    near = [{j for a, b in links for i, j in ((a, b), (b, a)) if i == v} for v in range(n)]
    bags: list[tuple[int, ...]] = []
    for k in range(count):
        rng = np.random.default_rng(k)
        for _ in range(REDRAWS):
            bag = [int(rng.integers(n))]
            while len(bag) < size:
                reach = sorted(set().union(*(near[v] for v in bag)) - set(bag))
                if not reach:
                    break
                bag.append(reach[int(rng.integers(len(reach)))])
            bag = tuple(sorted(bag))
            if len(bag) == size and bag not in bags:
                bags.append(bag)
                break
        else:
            break
    return bags


@cache
def dataset_bags(folder: str, size: int, count: int) -> tuple[str, ...]:
    """The bags of a dataset folder (`Unit.bag`: image names, space-separated)."""
    source = Source.of(Path(folder))
    model, seen_of = source.cameras(), source.seen()
    cams = [c for _, c in model]
    seen = [seen_of.get(n, np.zeros(0, np.int64)) for n, _ in model]
    links, _ = covisible_pairs(cams, seen, MIN_SHARED)
    bags = draw_bags(len(cams), links, size, count)
    if not bags:
        raise BenchError(
            f"{folder}: no {size} of its images are co-visible (viewing directions within "
            f"{COVISIBLE_DEG:g} deg or {MIN_SHARED} common model points); use a smaller --bag-size"
        )
    return tuple(" ".join(model[i][0] for i in bag) for bag in bags)


def bag_views(views, bag: str) -> tuple[int, ...]:
    """The indices in `views` of a bag's images (`Unit.bag`); none where the unit reads no
    bag, or a bag of every view (which is the entry itself)."""
    names = bag.split()
    if not 0 < len(names) < len(views):
        return ()
    index = {v.name: i for i, v in enumerate(views)}
    return tuple(index[n] for n in names)


def bag_truth(entry: Path, fronts: dict[str, FrontEnd]):
    """The ground truth of a bag's views (the evaluation side's: the model's poses)."""
    names = [v.name for v in next(iter(fronts.values())).views]
    posed = fronts[RIG].views if RIG in fronts else _named(load_views(entry), names)
    pools = next(iter(fronts.values())).pools
    return scene_truth(entry, [v.camera for v in posed], [v.name for v in posed], pools)


def _named(views, names: list[str]):
    """The views of `names`, in that order."""
    by_name = {v.name: v for v in views}
    return [by_name[n] for n in names]
