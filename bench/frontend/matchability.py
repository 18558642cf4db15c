"""`matchable`: an own-image selector that keeps the candidates a model predicts to be
matchable in another view, learned from the renders' exact labels
(`bench.harness.matchability`; docs/matchability.md).

It reads the view's own image and candidates only (`FEATURES`), never another view and
never the truth; the model is a gradient-boosted tree classifier (scikit-learn) shipped in
the package (`SHIPPED_MODEL`). The file holds one model per rendered scene type trained
without it (`PolicyInput.scene` picks the one that never saw the scene: a rendered verdict
never scores a scene type its model was trained on) and one trained on every type, for
any other scene (a photograph).
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bench import BenchError
from bench.frontend.features import descriptor_distances, nearest_two
from bench.frontend.policies import PolicyConfig, PolicyInput, policy
from bench.memo import digest, last_call

FEATURES = (
    "log_sigma",
    "log_response",
    "twins",
    "border_scale",
    "contrast",
    "distinct",
)
"""The model's inputs, each from the candidate's own image, with its reason:

* `log_sigma`: log2 of the scale (px). A coarse extremum survives the viewpoint, resolution
  and noise changes between two images better than a fine one (COLMAP's own order); one
  coarser than COLMAP's octaves is located on a few samples of image.
* `log_response`: log10 of the DoG contrast. A faint extremum is moved by noise (Lowe 2004).
* `twins`: how many candidates share its location (one per orientation). Each twin's
  descriptor is a second candidate for the same point, one the ratio test may confuse.
* `border_scale`: distance to the nearest image edge over the keypoint's diameter. A
  descriptor window cut by the edge is computed on padding.
* `contrast`: the grey level's standard deviation in a 15 px window, over the image's. A
  point on a flat patch has a descriptor of noise.
* `distinct`: the ratio of the nearest to the second-nearest descriptor distance among the
  view's own candidates at other locations (2 px or farther). The ratio test removes a
  match whose descriptor repeats, and repeated texture repeats within the image as in the
  other views (facades, foliage, procedural textures).

Not features (docs/matchability.md, measured on the held-out scene types): where the
candidate lies in the image (its distance to the edge over the image's side taught the
model where the training scenes put their matchable surfaces: held out, vegetation's
precision at 256 fell from 0.20 without it to 0.10 with it), and the ranks of scale and
response within the view (the mean held-out precision at 256 fell by 0.04 with them)."""

TWIN_PX = 2.0
"""Candidates closer than this share a location (`twins`, `distinct`)."""
CONTRAST_WINDOW = 15
"""The side of the window of `contrast` (px)."""
ROWS = 2048
"""Candidates per block of the distance matrix in `distinct`."""
VIEWS_REMEMBERED = 128
"""The views whose order a worker keeps (`_view_order`): every view of a dense scene under
each geometry granted, several times over."""

SHIPPED_MODEL = Path(__file__).with_name("matchability_model.pkl")
EVERY_TYPE = ""
"""The key of the model trained on every rendered scene type."""


def features(inp: PolicyInput) -> np.ndarray:
    """(N, len(FEATURES)) float64: each candidate's `FEATURES`, in their order."""
    c, cam = inp.candidates, inp.view.camera
    n = len(c)
    if n == 0:
        return np.zeros((0, len(FEATURES)))
    x, y = c.xy[:, 0], c.xy[:, 1]
    edge = np.minimum.reduce([x, y, cam.width - x, cam.height - y]).clip(0)
    twins, distinct = _own_neighbours(c.xy, c.descriptors)
    return np.stack(
        [
            np.log2(np.maximum(c.size / 2, 1e-3)),
            np.log10(np.maximum(c.response, 1e-6)),
            twins,
            edge / np.maximum(c.size, 1e-3),
            _contrast(inp.view.gray, c.xy),
            distinct,
        ],
        1,
    )


def _own_neighbours(xy: np.ndarray, desc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate: the candidates at its location (itself included), and the ratio of its
    nearest to second-nearest descriptor distance among those elsewhere (1 without two;
    1 for a whole block of `ROWS` where one of its candidates has fewer than two elsewhere)."""
    n = len(xy)
    a, b = _twin_pairs(xy)
    twins = 1.0 + np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    ratio = np.ones(n)
    rows_of, cols_of = np.r_[a, b, np.arange(n)], np.r_[b, a, np.arange(n)]
    for lo in range(0, n, ROWS):
        hi = min(lo + ROWS, n)
        if n - twins[lo:hi].min() < 2:
            continue
        D = descriptor_distances(desc[lo:hi], desc)
        mine = (rows_of >= lo) & (rows_of < hi)
        D[rows_of[mine] - lo, cols_of[mine]] = np.inf
        _, first, second = nearest_two(D)
        ok = np.isfinite(second) & (second > 0)
        ratio[lo:hi] = np.where(ok, first / np.where(ok, second, 1), 1.0)
    return twins, ratio


def _twin_pairs(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i < j) of candidates closer than `TWIN_PX`: found by a k-d tree within a
    slightly larger radius, then kept by the distance in `xy`'s own precision, as the
    definition computes it (`np.linalg.norm` of the difference)."""
    pairs = cKDTree(xy).query_pairs(TWIN_PX * 1.001 + 1e-3, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    near = np.linalg.norm(xy[i] - xy[j], axis=1) < TWIN_PX
    return i[near], j[near]


def _contrast(gray: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """The grey level's standard deviation in a `CONTRAST_WINDOW` window at each point, over
    the whole image's."""
    g = gray.astype(np.float64)
    k = (CONTRAST_WINDOW, CONTRAST_WINDOW)
    mean, sq = cv2.blur(g, k), cv2.blur(g * g, k)
    local = np.sqrt(np.maximum(sq - mean * mean, 0))
    col = np.clip(xy[:, 0].astype(int), 0, g.shape[1] - 1)
    row = np.clip(xy[:, 1].astype(int), 0, g.shape[0] - 1)
    return local[row, col] / max(float(g.std()), 1e-6)


@cache
def read_models(path: str) -> dict:
    """The record of a model file of `bench train-matchability`: `models` (held-out scene
    type, or `EVERY_TYPE`, to a fitted regressor), `features`, `seeds`, `scenes`."""
    file = Path(path) if path else SHIPPED_MODEL
    try:
        record = pickle.loads(file.read_bytes())
        if tuple(record["features"]) != FEATURES:
            raise ValueError(f"its features are {record['features']}, not {FEATURES}")
        return record
    except (OSError, ValueError, KeyError, TypeError, pickle.UnpicklingError) as e:
        raise BenchError(f"cannot read the matchability model {file}: {e}") from e


def model_for(record: dict, scene: str):
    """The model that never saw `scene`: the one trained without its type where it is a
    rendered type, else the one trained on every type."""
    return record["models"].get(scene, record["models"][EVERY_TYPE])


def predicted_order(model, X: np.ndarray) -> np.ndarray:
    """Indices by descending predicted probability of being matchable (ties by index)."""
    if not len(X):
        return np.zeros(0, np.int64)
    p = model.predict_proba(X)[:, 1]
    return np.lexsort((np.arange(len(p)), -p))


@dataclass(frozen=True)
class MatchableConfig(PolicyConfig):
    """`matchable`'s settings."""

    matchability_model: str = ""
    """`matchable`: the model file written by `bench train-matchability` (empty: the one
    shipped with the package, bench/frontend/matchability_model.pkl)."""

    def inputs(self) -> list[Path]:
        """The files whose content decides the policy's selections."""
        return [Path(self.matchability_model) if self.matchability_model else SHIPPED_MODEL]


@policy(
    "matchable",
    "Predicted matchability (own image; learned on renders)",
    pool="sift",
    config=MatchableConfig,
)
def matchable_policy(inp, budget, rng, cfg):
    """The B candidates most probably matchable in another view, by the model of their
    own-image `FEATURES`. No spatial spread and no orientation rule: neither moved the
    held-out precision at B (docs/matchability.md)."""
    return _view_order(inp, cfg.matchability_model)[:budget]


def _one_view(inp: PolicyInput, model_file: str) -> tuple:
    """What `_view_order` reads: the model's file and scene, the view's image and candidates."""
    c = inp.candidates
    arrays = (inp.view.gray, c.xy, c.size, c.response, c.descriptors)
    return model_file, inp.scene, inp.view.camera.width, inp.view.camera.height, digest(*arrays)


@last_call(_one_view, size=VIEWS_REMEMBERED, hold=False)
def _view_order(inp: PolicyInput, model_file: str) -> np.ndarray:
    """A view's candidates by predicted matchability, whatever the budget: computed once per
    view on a worker for the units of every budget (the features take 0.01-0.3 s a view)."""
    model = model_for(read_models(model_file), inp.scene)
    return predicted_order(model, features(inp))
