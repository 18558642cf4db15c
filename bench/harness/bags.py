"""Bags: a dataset scored on random co-visible subsets of its images, as the Image Matching
Challenge scores a scene (docs/protocol.md, "Verdicts and their power").

Bag k of a dataset is drawn by a generator seeded with k (`draw_bags`): a first image at
random, then one at a time an image drawn at random among those co-visible with an image
already in the bag, until the bag's size; a draw that repeats an earlier bag is drawn
again (`REDRAWS` times at most; the bags are then fewer). Co-visibility is the `pairs`
task's, from the dataset's model alone: at least `MIN_SHARED` common model points, else
viewing directions within `COVISIBLE_DEG` with overlapping frustums. A dataset with no
more images than the bag's size is one bag of all of them.

A bag is a scene of its own to the units that read it (`bag_scene`): its views, their
candidates (the dataset's, detected once per image and cached), the signals computed on
the bag's views alone (those that read other views see only the bag's), and the ground
truth of its views. The bag's identity goes into its rows (`BAG`: its image names,
space-separated; `views`: its size).
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from itertools import combinations
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.evaluation.relative import MIN_SHARED
from bench.evaluation.truth import COVISIBLE_DEG, _facing, scene_truth
from bench.frontend.colmap_model import points_seen, read_model
from bench.frontend.geometry import RIG
from bench.frontend.signals import SIGNALS, compute_signals
from bench.frontend.stage import FrontEnd
from bench.frontend.views import Source, load_views

BAG = "bag"
"""The `runs.csv` column naming a dataset row's bag: its image names, space-separated."""
REDRAWS = 100
"""The draws of one bag that may repeat an earlier bag before the bags stop."""
VIEW_ALONE = ("repeatability_redetect",)
"""The costly signal that reads one view alone (four perturbed re-detections of it): a
bag takes the dataset's (`bench.frontend.signals.compute_signals` computes the others
cheaply, or, as ambiguity, parallax and epipolar, from the other views)."""
DEFAULT_SIZE, DEFAULT_COUNT = 6, 10
"""The default bag: the sparse regime's 6 views, 10 bags (docs/protocol.md)."""


def covisible(cams, seen: list[np.ndarray]) -> set[tuple[int, int]]:
    """The pairs (i < j) of views that see the same surface: at least `MIN_SHARED` common
    model points where the model has points, else viewing directions within
    `COVISIBLE_DEG` with overlapping frustums."""
    pairs = combinations(range(len(cams)), 2)
    if any(len(s) for s in seen):
        return {(i, j) for i, j in pairs if len(np.intersect1d(seen[i], seen[j])) >= MIN_SHARED}
    return {(i, j) for i, j in pairs if _facing(cams[i], cams[j])}


def draw_bags(n: int, links: set[tuple[int, int]], size: int, count: int) -> list[tuple[int, ...]]:
    """`count` distinct bags of `size` of the views 0..n-1, each grown at random along the
    co-visibility `links` by a generator seeded with its number (module docstring); one bag
    of every view where `size` >= n (or `size` is 0)."""
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
def dataset_bags(folder: str, size: int, count: int) -> tuple[tuple[int, ...], ...]:
    """The bags of a dataset folder (indices into its model's views, in name order)."""
    model = read_model(Source.of(Path(folder)).model)
    seen_of = points_seen(Source.of(Path(folder)).model)
    cams = [c for _, c in model]
    seen = [seen_of.get(n, np.zeros(0, np.int64)) for n, _ in model]
    bags = draw_bags(len(cams), covisible(cams, seen), size, count)
    if not bags:
        raise BenchError(
            f"{folder}: no {size} of its images are co-visible (viewing directions within "
            f"{COVISIBLE_DEG:g} deg or {MIN_SHARED} common model points); use a smaller --bag-size"
        )
    return tuple(bags)


def bag_names(folder: str, bag: tuple[int, ...]) -> str:
    """A bag's identity in its rows: its image names, space-separated."""
    names = [n for n, _ in read_model(Source.of(Path(folder)).model)]
    return " ".join(names[i] for i in bag)


def bag_front(full: FrontEnd, bag: tuple[int, ...], det, sig) -> FrontEnd:
    """The front end of a bag: the dataset's candidates of its views and the signals that
    read a view alone (`VIEW_ALONE`, the costly re-detection among them) as the dataset's
    front end computed them, with the others computed on the bag's views alone, as
    `bench.frontend.stage.compute` computes them (on each view downscaled to
    `det.max_image_size`); their seconds are the dataset's share per view of the view-alone
    signals and detection, and the bag's own of the others."""
    views = [full.views[i] for i in bag]
    work = [v.scale_to(det.max_image_size) for v in views]
    pools = [full.pools[i] for i in bag]
    scaled = [c.scaled(sx, sy) for c, (_, sx, sy) in zip(pools, work)]
    wanted = tuple(s for s in SIGNALS if s not in VIEW_ALONE)
    sigs, seconds = compute_signals([v for v, _, _ in work], scaled, det, sig, wanted)
    sigs = [
        replace(g, **{s: getattr(full.signals[i], s) for s in VIEW_ALONE})
        for g, i in zip(sigs, bag)
    ]
    share = len(bag) / len(full.views)
    seconds |= {k: full.seconds[k] * share for k in ("detect", *VIEW_ALONE)}
    return FrontEnd(views, pools, sigs, seconds, cached=False)


def bag_fronts(fronts: dict[str, FrontEnd], bag: tuple[int, ...], det, sig) -> dict:
    """`bag_front` under each geometry granted."""
    return {g: bag_front(fe, bag, det, sig) for g, fe in fronts.items()}


def bag_truth(entry: Path, fronts: dict[str, FrontEnd], bag: tuple[int, ...]):
    """The ground truth of a bag's views (the evaluation side's: the model's poses)."""
    posed = fronts[RIG].views if RIG in fronts else [load_views(entry)[i] for i in bag]
    pools = next(iter(fronts.values())).pools
    return scene_truth(entry, [v.camera for v in posed], [v.name for v in posed], pools)
