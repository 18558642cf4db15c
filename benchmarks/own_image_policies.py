"""Candidate own-image policies for issue 53 (`bench run --policy-module`), each with its
reason stated before it was measured (docs/protocol.md, "The own-image question"). Each
sees its own view's candidates alone (no signal of other views).

* `scale` (measured here first, now the package's: `bench.frontend.policies.scale_policy`):
  the B largest-scale candidates, ties by response: COLMAP's own order when it caps its
  SIFT (`colmap-b`), applied to the candidate pool. Reason, for photographs in general: an
  extremum found at a coarse scale of the scale space survives the changes of viewpoint,
  resolution and noise between two photographs of a scene better than a fine one (Lowe
  2004, section 4; the restricted-keypoint practice). If it reaches `colmap-b`, the gap
  was the order in which the policies keep candidates; if not, it is in the pool.
* `coarse-response`: the strongest responses among the candidates at or above the view's
  median scale (the finest half left out), B of them (all of that half, then the finest
  by response, where it holds fewer). Reason: the response ranks contrast, and at the
  finest scales of any camera image contrast is set by noise, aliasing and
  demosaicing, which do not repeat between views; above the median it ranks real
  structure. The cut is the view's own median, no constant fitted to a scene.
"""

from __future__ import annotations

import numpy as np

from bench.frontend.policies import policy


@policy("coarse-response", "Response above the median scale", role="baseline")
def coarse_response_policy(inp, budget, rng, cfg):
    c = inp.candidates
    coarse = c.size >= np.median(c.size)
    order = np.lexsort((np.arange(len(c.size)), -c.response, ~coarse))
    return order[:budget]


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(
        description="A policy module, not a script: measure its policies with `bench run "
        "--policy-module benchmarks/own_image_policies.py --methods coarse-response,scale,"
        "response --budget 128,256,512` (docs/protocol.md, the own-image question)."
    ).parse_args()
