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
* `repeatable-scale` (second round): the candidates re-detected under the most of the four
  fixed perturbations of their own image (`repeatability_redetect`: a rotation, a tilt,
  blur with noise, an exposure change), the largest scales first among equals. Reason:
  `colmap-b`'s keypoints fall in tracks of three or more views more often than
  `scale`'s; a keypoint that survives its own image's perturbations is the one a second
  photograph, which perturbs it too, detects again, and scale orders those that survive
  alike. It reads one image (the signal's perturbations are of the view alone).
* `distinct-scale` (second round): the largest scales among the candidates whose nearest
  other descriptor in their own image lies at least the view's median distance away
  (`distinctiveness`), then the rest by scale. Reason: a descriptor with a near twin in
  its own image (repeated structure: windows, tiles, leaves) fails the ratio test of
  matching in every other view; leaving out the less distinct half is the own image's
  view of the ambiguity the `views` policies measure across views. The cut is the view's
  own median, as above.
* `peak-scale` (third round, after the two above fell below `scale`; now the package's:
  `bench.frontend.policies.peak_scale_policy`): the largest scales
  among the candidates whose response reaches COLMAP's SIFT peak threshold (0.02 per
  octave of 3 levels, on intensities in [0, 1]: the DoG contrast below which Lowe and
  COLMAP discard an extremum as moved by noise), then the rest by scale. Reason: the pool
  is detected at a contrast threshold four times lower (`DetectorConfig.sift_contrast`,
  so that it holds several times the budget), and 5-33 % of `scale`'s 256 coarsest on the
  seed-0 renders lie below COLMAP's threshold: coarse, faint blobs that no second
  photograph places alike. The threshold is the peer's default, not fitted.
* `octave-scale` (fourth round, after `benchmarks/pool_apart.py` found COLMAP's keypoints
  through the policies' back end level with `colmap-b` where `peak-scale`'s are not; now
  the package's: `bench.frontend.policies.octave_scale_policy`): `peak-scale` within
  COLMAP's scale range, the candidates coarser than the coarsest scale COLMAP's SIFT
  extracts put last (`COLMAP_MAX_SIGMA`). Reason, for photographs in
  general: COLMAP's default extraction spans 4 octaves from the upsampled image
  (`first_octave` -1, `num_octaves` 4), so it never keeps an extremum coarser than sigma
  = 1.6 x 2^(1/3) x 2^3 = 16 px, at any image size; OpenCV's pool holds every octave down
  to a few samples of image (sigma up to 26 px on the sparse facade, 53 px on the dense
  corridor), and `peak-scale` kept 4-11 such blobs per view at 128 there. Their extremum
  is located to a sample of an octave whose pixels are 8-32 image pixels, against the back
  end's 4 px verification threshold. The cut is the peer's default octave range, not
  fitted. Looked at before the grid ran: the seven cells of the 128 gap (sparse facade,
  dense corridor), one back-end seed: 3 up, 2 down, 2 level.
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


@policy(
    "repeatable-scale",
    "Re-detected, then largest scale",
    role="baseline",
    reads=("repeatability_redetect",),
)
def repeatable_scale_policy(inp, budget, rng, cfg):
    c, r = inp.candidates, inp.signals.repeatability_redetect
    return np.lexsort((np.arange(len(c.size)), -c.response, -c.size, -r))[:budget]


@policy(
    "distinct-scale", "Distinct, then largest scale", role="baseline", reads=("distinctiveness",)
)
def distinct_scale_policy(inp, budget, rng, cfg):
    c, q = inp.candidates, inp.signals.distinctiveness
    distinct = q >= np.median(q)
    return np.lexsort((np.arange(len(c.size)), -c.response, -c.size, ~distinct))[:budget]


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(
        description="A policy module, not a script: measure its policies with `bench run "
        "--policy-module benchmarks/own_image_policies.py --methods coarse-response,"
        "repeatable-scale,distinct-scale,peak-scale,scale,response --budget 128,256,512` (docs/protocol.md, the own-image question)."
    ).parse_args()
