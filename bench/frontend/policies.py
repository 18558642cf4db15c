"""Feature selection policies (paper, section 4.2): one registry, one contract.

A policy receives a `PolicyInput` (the view's image and calibration, its candidates and
their signals: no ground truth can reach it) with a budget B and a seeded generator, and
returns exactly min(B, N) distinct candidate indices. A selection is a set: `select`
returns it in ascending order, so the order a policy lists its indices in never changes
what the matcher sees. Adding a policy is one decorated
function; `bench run --policy-module FILE` (or an installed package's `bench.policies`
entry point) registers policies from outside the package (`bench.frontend.plugins`).

The contract, checked on every call (`select`), each rule named in its error:
exact budget (min(B, N) indices; a whole-pool method such as `all` the whole pool), distinct indices, valid range
(0 <= index < N); and no ground truth (checked on a policy module's source before it runs).
"""

from __future__ import annotations

import inspect
import json
import math
import traceback
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from functools import cache
from pathlib import Path

import numpy as np

from bench import BenchError, MethodFailed
from bench.frontend.features import Candidates, tile_of
from bench.frontend.pools import strongest_first
from bench.frontend.signals import SIGNALS, Signals
from bench.frontend.views import View
from bench.vocabulary import METHODS, MULTI_VIEW, PER_VIEW, SETTINGS, Method, declare_method


@dataclass(frozen=True)
class PolicyInput:
    """Everything a policy may look at: arrays and a file name, no path to any file."""

    view: View
    """The image: `index` (int, its position in the scene), `name` (its file name),
    `image` (H, W, 3) uint8 sRGB in RGB order, `camera` (`bench.camera.Camera`: `width`,
    `height` in px; `fx`, `fy`, `cx`, `cy` in px; `R` (3, 3), `t` (3,) world to camera,
    the identity where `posed` is False, as in the sfm task)."""
    candidates: Candidates
    """The view's N candidate keypoints, (N, ...) arrays indexed alike (`Candidates`)."""
    signals: Signals
    """One (N,) float array per signal, each in [0, 1] (`Signals`)."""
    scene: str = ""
    """The scene's name: a rendered scene's type, a photo set's folder name (what the
    user knows of a capture; `matchable` takes the model that never saw it)."""


@dataclass(frozen=True)
class Weights:
    """The adaptive score's weight of each signal, by name: s = w_t t + w_r r + w_q q +
    w_p p - w_a a (the paper's values; ambiguity counts against a candidate)."""

    texture: float = 0.28
    repeatability: float = 0.27
    distinctiveness: float = 0.22
    parallax: float = 0.19
    ambiguity: float = 0.20


@dataclass(frozen=True)
class PolicyConfig:
    """Settings shared by the selection policies; a policy's own settings are a subclass
    of it, declared with the policy (`policy(..., config=...)`) and given to it alone."""

    weights: Weights = Weights()
    """Adaptive score weights for texture, repeatability, distinctiveness, parallax and
    ambiguity: s = w_t t + w_r r + w_q q + w_p p - w_a a (the paper's values)."""
    tiles: tuple[int, int] = (8, 6)
    """Columns x rows of the tile grid used by the grid policy and the adaptive tile cap."""
    cap_factor: float = 2.0
    """Adaptive soft cap: a tile may hold at most cap_factor x B / (non-empty tiles)
    selections, until the cap must grow to fill the budget."""
    modules: tuple[str, ...] = ()
    """Python files whose policies are registered before selecting (`--policy-module`)."""

    def validate(self) -> PolicyConfig:
        values = [getattr(self.weights, f.name) for f in fields(Weights)]
        if not all(isinstance(w, int | float) and math.isfinite(w) for w in values):
            raise BenchError(f"weights must be five numbers (t, r, q, p, a), got {values!r}")
        if min(self.tiles) <= 0 or self.cap_factor <= 0:
            raise BenchError("tiles and cap_factor must be positive")
        return self


def own_fields(cls: type) -> list[str]:
    """The fields of a policy's settings class that are its own (not `PolicyConfig`'s)."""
    shared = {f.name for f in fields(PolicyConfig)}
    return [f.name for f in fields(cls) if f.name not in shared]


def settings_for(name: str, cfg: PolicyConfig, own: dict | None = None) -> PolicyConfig:
    """The settings a method is given: the shared ones of `cfg` with its own (`own`, else
    those `cfg` carries, else their defaults); `cfg` itself for a method without any."""
    cls = SETTINGS.get(name)
    if cls is None:
        return cfg
    shared = {f.name: getattr(cfg, f.name) for f in fields(PolicyConfig)}
    if own is None:
        own = {k: getattr(cfg, k) for k in own_fields(cls) if hasattr(cfg, k)}
    return cls(**shared, **own)


Policy = Callable[[PolicyInput, int, np.random.Generator, PolicyConfig], np.ndarray]
POLICIES: dict[str, Policy] = {}
"""The selection function of every per-view policy (its metadata: `bench.vocabulary.METHODS`)."""
MultiviewPolicy = Callable[[list[PolicyInput], int, PolicyConfig, Callable], tuple[list, list]]
MULTIVIEW: dict[str, MultiviewPolicy] = {}
"""The selection function of every multi-view policy: (every view's input, budget,
settings, `match`: selections per view -> their verified pairs) -> (selection per view,
diagnostics per round)."""


def _check_reads(name: str, reads) -> None:
    unknown = [s for s in reads if s not in SIGNALS]
    if unknown:
        raise BenchError(
            f"policy {name} reads unknown signal {unknown[0]!r}; valid: {', '.join(SIGNALS)}"
        )


def register_policy(method: Method, fn: Policy, config: type | None = None) -> Policy:
    """Register a per-view policy's declaration (its kind: `PER_VIEW`), its selection
    function and the class of its own settings (`policy` does this for a decorated one)."""
    _check_reads(method.name, method.reads)
    declare_method(replace(method, kind=PER_VIEW), settings=config)
    POLICIES[method.name] = fn
    return fn


def policy(
    name: str,
    label: str | None = None,
    role: str = "contender",
    whole_pool: bool = False,
    reads: tuple[str, ...] = (),
    config: type | None = None,
    pool: str = "",
) -> Callable[[Policy], Policy]:
    """Register a per-view policy under a name no other method has: its display label
    (default: the name), its role (`bench.vocabulary.ROLES`), whether it takes the whole
    pool (then it runs once per scene and seed, as budget 0), the signals it reads (for its
    reported cost, and so that `bench select` computes the costly ones), the class of
    its own settings (a `PolicyConfig` subclass; `--set <name>.<field>=value`) and the
    detector whose pool it needs (`Method.pool`; empty: any)."""
    method = Method(name, label or name, role, whole_pool, tuple(reads), pool)
    _check_reads(name, reads)
    return lambda fn: register_policy(method, fn, config)


def multiview_policy(
    name: str,
    label: str | None = None,
    role: str = "contender",
    reads: tuple[str, ...] = (),
    config: type | None = None,
) -> Callable[[MultiviewPolicy], MultiviewPolicy]:
    """Register a multi-view policy (`MULTIVIEW`) under a name no other method has; the
    arguments as `policy`'s."""
    _check_reads(name, reads)

    def register(fn: MultiviewPolicy) -> MultiviewPolicy:
        method = Method(name, label or name, role, reads=tuple(reads), kind=MULTI_VIEW)
        declare_method(method, settings=config)
        MULTIVIEW[name] = fn
        return fn

    return register


def check_methods(names) -> list[str]:
    """Refuse, in one line, a name no method has declared."""
    unknown = [n for n in names if n not in METHODS]
    if unknown:
        raise BenchError(f"unknown method {unknown[0]!r}; valid: {', '.join(METHODS)}")
    return list(names)


def contract_violation(idx: np.ndarray, want: int, n: int) -> str | None:
    """The first contract rule that a selection breaks, or None."""
    if len(idx) != want:
        return f"exact budget: {len(idx)} indices returned, {want} expected"
    if len(np.unique(idx)) != len(idx):
        return f"distinct indices: {len(idx) - len(np.unique(idx))} repeated"
    if len(idx) and (idx.min() < 0 or idx.max() >= n):
        return f"valid range: indices must lie in [0, {n}), got {idx.min()}..{idx.max()}"
    return None


class PolicyFailed(MethodFailed):
    """A policy failed (`MethodFailed`), in a view (`view`)."""

    def __init__(self, policy: str, what: str, view: View, where: str):
        message = f"policy {policy} {what} (view {view.index} {view.name!r}, at {where})"
        super().__init__(policy, what, where, message)
        self.view = view


def code_line(fn: Callable, error: BaseException | None = None) -> str:
    """`file:line` of a policy: the last line of its file in `error`'s traceback (where it
    raised), else the line that defines it."""
    code = getattr(inspect.unwrap(fn), "__code__", None)
    if code is None:
        return repr(fn)
    frames = traceback.extract_tb(error.__traceback__) if error is not None else []
    line = next(
        (f.lineno for f in reversed(frames) if f.filename == code.co_filename),
        code.co_firstlineno,
    )
    return f"{code.co_filename}:{line}"


def _indices(out) -> tuple[np.ndarray | None, str | None]:
    """A policy's return value as a flat index array, or what is wrong with it."""
    if out is None:
        return None, "returned None (missing return?)"
    if isinstance(out, tuple):
        return None, f"returned a tuple of {len(out)}, not one array of candidate indices"
    kind = type(out).__name__
    try:
        idx = np.asarray(out)
    except ValueError as e:  # a ragged list
        return None, f"returned a {kind} that is not one array of indices: {e}"
    if idx.ndim == 0 or idx.dtype.kind in "OSUV":
        return None, f"returned a {kind}, not an array of candidate indices"
    idx = idx.reshape(-1)
    if idx.dtype.kind not in "iu":
        return None, f"broke the contract rule 'integer indices': {idx.dtype}"
    return idx.astype(np.int64), None


def select(
    name: str,
    inp: PolicyInput,
    budget: int,
    rng: np.random.Generator,
    cfg: PolicyConfig = PolicyConfig(),
) -> np.ndarray:
    """Run a policy, check its contract and return its selection in ascending order (module
    docstring); a policy that raises or breaks the contract is a `PolicyFailed`."""
    if name not in POLICIES:
        check_methods([name])
        raise BenchError(f"{name} is not a selection policy (a reference or a peer)")
    whole = METHODS[name].whole_pool
    if budget <= 0 and not whole:
        raise BenchError(f"budget must be positive, got {budget}")
    fn = POLICIES[name]
    cfg = settings_for(name, cfg)
    try:
        out = fn(inp, budget, rng, cfg)
    except BenchError:
        raise
    except (Exception, SystemExit) as e:  # a policy ends no run, not even with sys.exit
        raise PolicyFailed(
            name, f"failed: {type(e).__name__}: {e}", inp.view, code_line(fn, e)
        ) from e
    idx, wrong = _indices(out)
    if wrong is None:
        n = len(inp.candidates)
        broken = contract_violation(idx, n if whole else min(budget, n), n)
        wrong = broken and f"broke the contract rule '{broken}'"
    if wrong:
        raise PolicyFailed(name, wrong, inp.view, code_line(fn))
    return np.sort(idx)


def adaptive_score(s: Signals, w: Weights, repeatability: np.ndarray | None = None) -> np.ndarray:
    """The paper's score s; `repeatability` replaces the cheap estimate (`adaptive` passes
    the re-detection signal)."""
    r = s.repeatability if repeatability is None else repeatability
    return (
        w.texture * s.texture
        + w.repeatability * r
        + w.distinctiveness * s.distinctiveness
        + w.parallax * s.parallax
        - w.ambiguity * s.ambiguity
    )


@policy("random", "Random budget", role="baseline")
def random_policy(inp, budget, rng, cfg):
    """A uniform random subset."""
    return rng.choice(len(inp.candidates), size=min(budget, len(inp.candidates)), replace=False)


@policy("texture", "Texture-only", role="baseline", reads=("texture",))
def texture_policy(inp, budget, rng, cfg):
    """The B candidates of highest texture."""
    return strongest_first(inp.signals.texture)[:budget]


@policy("grid", "Uniform grid", role="baseline", reads=("texture",))
def grid_policy(inp, budget, rng, cfg):
    """Equal quota per tile, best texture first inside each tile; quota a tile cannot use
    goes to the others: round k takes every tile's k-th best candidate, ordered by texture."""
    cam = inp.view.camera
    tile = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
    order = strongest_first(inp.signals.texture)
    rank = np.empty(len(order), int)
    for t in np.unique(tile):
        members = order[tile[order] == t]
        rank[members] = np.arange(len(members))
    by_round = np.lexsort((np.arange(len(order)), -inp.signals.texture, rank))
    return by_round[:budget]


ADAPTIVE_SIGNALS = ("texture", "repeatability", "distinctiveness", "ambiguity", "parallax")
"""The signals of `adaptive-fast`, `adaptive-loop`, `learned` and `cross-view`: the paper's
five with the cheap repeatability estimate."""


def capped_greedy(
    score: np.ndarray, inp: PolicyInput, budget: int, cfg: PolicyConfig
) -> np.ndarray:
    """Greedy by score under a soft per-tile cap: at most ceil(cap_factor * B / T) per tile
    (T = tiles holding candidates); only if the pool cannot fill B under that cap is it
    raised, one step at a time, until the budget is met."""
    cam = inp.view.camera
    tile = tile_of(inp.candidates.xy, cam.width, cam.height, cfg.tiles)
    order = strongest_first(score)
    want = min(budget, len(order))
    cap = math.ceil(cfg.cap_factor * budget / max(len(np.unique(tile)), 1))
    picked: list[int] = []
    chosen = np.zeros(len(order), bool)
    count = np.zeros(cfg.tiles[0] * cfg.tiles[1], int)
    while len(picked) < want:
        for i in order:
            if len(picked) == want:
                break
            if not chosen[i] and count[tile[i]] < cap:
                chosen[i] = True
                count[tile[i]] += 1
                picked.append(i)
        cap += 1
    return np.array(picked, dtype=np.int64)


@policy(
    "adaptive",
    "Adaptive optimized",
    reads=("texture", "repeatability_redetect", "distinctiveness", "ambiguity", "parallax"),
)
def adaptive_policy(inp, budget, rng, cfg):
    """The paper's score s (its repeatability: four re-detections per view) under the soft
    tile cap of `capped_greedy`."""
    s = inp.signals
    return capped_greedy(adaptive_score(s, cfg.weights, s.repeatability_redetect), inp, budget, cfg)


@policy("adaptive-fast", "Adaptive, cheap repeatability", reads=ADAPTIVE_SIGNALS)
def adaptive_fast_policy(inp, budget, rng, cfg):
    """`adaptive` with the cheap repeatability estimate (no re-detection)."""
    return capped_greedy(adaptive_score(inp.signals, cfg.weights), inp, budget, cfg)


@dataclass(frozen=True)
class CrossViewConfig(PolicyConfig):
    """`cross-view`'s settings."""

    epipolar_weight: float = 0.28
    """Weight of the epipolar signal in the `cross-view` score (the paper's largest weight,
    fixed before any run)."""


@policy(
    "cross-view",
    "Adaptive + epipolar signal",
    reads=(*ADAPTIVE_SIGNALS, "epipolar"),
    config=CrossViewConfig,
)
def cross_view_policy(inp, budget, rng, cfg):
    """`adaptive-fast` plus epipolar_weight x the epipolar signal: candidates with a
    ratio-passing match on their epipolar lines in other views first (beyond the paper)."""
    score = adaptive_score(inp.signals, cfg.weights) + cfg.epipolar_weight * inp.signals.epipolar
    return capped_greedy(score, inp, budget, cfg)


MIN_PARALLAX = 0.15
"""`learned`'s parallax constraint: candidates whose parallax signal is below this (1.5
degrees, COLMAP's minimum triangulation angle, at the depth prior) come last."""


SHIPPED_WEIGHTS = Path(__file__).with_name("learned_weights.json")


def weights_file(path: str) -> Path:
    """The weights file a `learned_weights` setting names."""
    return Path(path) if path else SHIPPED_WEIGHTS


@cache
def learned_weights(path: str) -> dict:
    """The weights (and training seeds) of a weights file of `bench train-weights` (see
    `bench.harness.training`)."""
    path = weights_file(path)
    try:
        data = json.loads(Path(path).read_text())
        return {k: float(data["weights"][k]) for k in ADAPTIVE_SIGNALS} | {"seeds": data["seeds"]}
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise BenchError(f"cannot read the learned weights {path}: {e}") from e


@dataclass(frozen=True)
class LearnedConfig(PolicyConfig):
    """`learned`'s settings."""

    learned_weights: str = ""
    """`learned`: the weights file written by `bench train-weights` (empty: the weights
    shipped with the package, bench/frontend/learned_weights.json)."""

    def inputs(self) -> list[Path]:
        """The files whose content decides the policy's selections."""
        return [weights_file(self.learned_weights)]


@policy("learned", "Learned weights", reads=ADAPTIVE_SIGNALS, config=LearnedConfig)
def learned_policy(inp, budget, rng, cfg):
    """The logit of a logistic model of "became an accurate point" over the five signals
    (weights fitted by `bench train-weights` on training seeds), under the adaptive tile
    cap (coverage) and a parallax constraint (MIN_PARALLAX)."""
    w = learned_weights(cfg.learned_weights)
    logit = sum(w[k] * getattr(inp.signals, k) for k in ADAPTIVE_SIGNALS)
    span = np.ptp(logit) if len(logit) else 0.0
    score = logit - (span + 1) * (inp.signals.parallax < MIN_PARALLAX)
    return capped_greedy(score, inp, budget, cfg)


@policy("response", "Detector response (top-B)", role="baseline")
def response_policy(inp, budget, rng, cfg):
    """The B strongest detector responses: what COLMAP-style and learned pipelines keep."""
    return strongest_first(inp.candidates.response)[:budget]


@policy("scale", "Largest scale (top-B)", role="baseline")
def scale_policy(inp, budget, rng, cfg):
    """The B largest-scale candidates, ties by response then index: COLMAP's own order
    when it caps its SIFT (`colmap-b`), on the pool. An extremum found at a coarse scale
    survives the changes of viewpoint, resolution and noise between two photographs of a
    scene better than a fine one (issue 53; docs/protocol.md, "The own-image question")."""
    c = inp.candidates
    return np.lexsort((np.arange(len(c.size)), -c.response, -c.size))[:budget]


PEAK_THRESHOLD = 0.02 / 3
"""COLMAP's SIFT peak threshold (its `peak_threshold` 0.02 over `octave_resolution` 3), in
the units of OpenCV's SIFT response: DoG contrast on intensities in [0, 1]."""


@policy("peak-scale", "Largest scale above COLMAP's peak threshold", role="baseline", pool="sift")
def peak_scale_policy(inp, budget, rng, cfg):
    """The B largest-scale candidates among those whose response reaches COLMAP's SIFT peak
    threshold (`PEAK_THRESHOLD`), then the fainter by scale: COLMAP's own order and cut
    when it caps its SIFT (`colmap-b`), on a pool detected at a contrast four times lower
    (`DetectorConfig.sift_contrast`), whose faint coarse blobs, moved by noise, no second
    photograph places alike (Lowe 2004; docs/protocol.md, "The own-image question")."""
    c = inp.candidates
    faint = c.response < PEAK_THRESHOLD
    return np.lexsort((np.arange(len(c.size)), -c.response, -c.size, faint))[:budget]


COLMAP_MAX_SIGMA = 1.6 * 2 ** (1 / 3) * 2**3
"""The coarsest scale sigma (px) of COLMAP's default SIFT extraction: VLFeat's base scale
1.6 x 2^(1/3), times 2^3 at the start of the fifth octave counted from the upsampled -1,
which COLMAP does not compute (`first_octave` -1, `num_octaves` 4)."""


@policy(
    "octave-scale",
    "Largest scale above COLMAP's peak threshold, within its octaves",
    role="baseline",
    pool="sift",
)
def octave_scale_policy(inp, budget, rng, cfg):
    """`peak-scale` within COLMAP's scale range: the candidates coarser than any COLMAP's
    SIFT extracts (`COLMAP_MAX_SIGMA`) last. COLMAP never keeps such an extremum, at any
    image size; the pool holds them down to a few samples of image (sigma up to 26 px on
    the sparse facade, 53 on the dense corridor), located to a sample of an octave whose
    pixels are 8-32 image pixels, against the back end's 4 px verification threshold
    (docs/protocol.md, "The own-image question")."""
    c = inp.candidates
    faint, coarse = c.response < PEAK_THRESHOLD, c.size / 2 > COLMAP_MAX_SIGMA
    return np.lexsort((np.arange(len(c.size)), -c.response, -c.size, faint, coarse))[:budget]


@policy("ssc", "SSC (Bailo 2018)", role="baseline")
def ssc_policy(inp, budget, rng, cfg):
    """Suppression via Square Covering (Bailo et al., "Efficient adaptive non-maximal
    suppression algorithms for homogeneous spatial keypoint distribution", Pattern
    Recognition Letters 2018): on response-ranked keypoints, a keypoint is kept unless a
    kept one covers its cell (a kept keypoint covers the grid cells of side w/2 within w
    of its own); binary search for the widest w that keeps at least B, whose first B (by
    response) are returned."""
    order = strongest_first(inp.candidates.response)
    xy = inp.candidates.xy[order]
    want = min(budget, len(order))
    cam = inp.view.camera

    def cover(w: float) -> np.ndarray:
        cell = w / 2
        cols = int(cam.width / cell) + 1
        rows = int(cam.height / cell) + 1
        covered = np.zeros((rows + 1, cols + 1), bool)
        keep = []
        reach = int(math.ceil(w / cell))
        for k, (x, y) in enumerate(xy):
            r, c = min(int(y / cell), rows), min(int(x / cell), cols)
            if covered[r, c]:
                continue
            keep.append(k)
            covered[max(r - reach, 0) : r + reach + 1, max(c - reach, 0) : c + reach + 1] = True
            if len(keep) >= want:
                break
        return np.array(keep, dtype=np.int64)

    lo, hi = 1.0, float(max(cam.width, cam.height))
    best = cover(lo)
    if len(best) < want:  # keypoints closer than a pixel: plain response order
        return order[:want]
    while hi - lo >= 0.5:  # the widest covering to half a pixel
        mid = (lo + hi) / 2
        kept = cover(mid)
        if len(kept) >= want:
            best, lo = kept, mid
        else:
            hi = mid
    return order[best[:want]]


@policy("quadtree", "Quadtree (ORB-SLAM)", role="baseline")
def quadtree_policy(inp, budget, rng, cfg):
    """ORB-SLAM's DistributeOctTree (Mur-Artal et al. 2015): split the image into
    quadrants, most populous first, until there are at least B cells or none can split;
    keep the strongest response per cell (the B strongest cells if there are more), and
    fill a shortfall with the next strongest keypoints."""
    xy, resp = inp.candidates.xy, inp.candidates.response
    want = min(budget, len(xy))
    cam = inp.view.camera
    cells = [(0.0, 0.0, float(cam.width), float(cam.height), np.arange(len(xy)))] if len(xy) else []
    while len(cells) < want:
        splittable = [k for k, c in enumerate(cells) if len(c[4]) > 1 and c[2] - c[0] > 1]
        if not splittable:
            break
        k = max(splittable, key=lambda k: (len(cells[k][4]), -k))
        x0, y0, x1, y1, members = cells.pop(k)
        mx, my = (x0 + x1) / 2, (y0 + y1) / 2
        for ax, ay, bx, by in (
            (x0, y0, mx, my),
            (mx, y0, x1, my),
            (x0, my, mx, y1),
            (mx, my, x1, y1),
        ):
            p = xy[members]
            inside = members[(p[:, 0] >= ax) & (p[:, 0] < bx) & (p[:, 1] >= ay) & (p[:, 1] < by)]
            if len(inside):
                cells.append((ax, ay, bx, by, inside))
    best = np.array([c[4][strongest_first(resp[c[4]])[0]] for c in cells], dtype=np.int64)
    best = best[strongest_first(resp[best])][:want]
    if len(best) < want:
        rest = np.setdiff1d(strongest_first(resp), best, assume_unique=True)
        rest = rest[strongest_first(resp[rest])]
        best = np.concatenate([best, rest[: want - len(best)]])
    return best


@policy("all", "All candidates (reference)", role="reference", whole_pool=True)
def all_policy(inp, budget, rng, cfg):
    """The whole pool, whatever the budget: the reference row."""
    return np.arange(len(inp.candidates))
