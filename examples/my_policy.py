"""An example policy from outside the package: `bench run --policy-module examples/my_policy.py
--methods texture,center-texture`.

A policy is a function (inputs, budget, rng, cfg) -> indices, registered with `@policy`.
It sees one view's image, calibration, candidates and signals (`PolicyInput`), never ground
truth, and must return exactly min(B, N) distinct indices into the candidates.
"""

import numpy as np

from bench.frontend.policies import policy


@policy("center-texture", "Texture, centre-weighted", reads=("texture",))
def center_texture(inp, budget, rng, cfg):
    """Texture, discounted by the distance from the image centre (a made-up prior)."""
    cam = inp.view.camera
    r = np.hypot(inp.candidates.xy[:, 0] - cam.cx, inp.candidates.xy[:, 1] - cam.cy)
    score = inp.signals.texture * (1 - 0.5 * r / r.max())
    return np.argsort(-score, kind="stable")[:budget]
