"""Developing a path-traced exposure into the 8-bit image a camera delivers.

A camera's image pipeline denoises its signal before it encodes it, and light in the world
carries no Monte Carlo noise: a photograph's illumination is smooth but for shadows and
shading edges, and its fine detail is the texture of the surfaces. A render at a few
samples per pixel is not: most of its noise is in the estimate of the light reaching each
pixel (the one-bounce indirect light, the sky's visibility), and at the front end's
contrast threshold that noise makes SIFT candidates a photograph does not have
(docs/scenes.md, "Render noise"). So the exposure is developed as a camera would, with the
denoiser applied to the light alone:

1. the light is separated from the texture: illumination = radiance / albedo (the `albedo`
   AOV of the same pass; where the albedo is 0, the radiance itself), as Mitsuba's
   own (OptiX) denoiser and every production denoiser guide themselves;
2. the illumination is encoded like an image (sRGB, relative to its 99.9th percentile),
   its noise measured there (`noise_sigma`), and denoised by OpenCV's non-local means with
   a strength of `denoise` times the measured noise: one constant for every scene and
   view, never tuned per scene; a cleaner exposure is denoised less;
3. the texture is put back: the radiance changes by albedo x the denoiser's change of the
   illumination (so the rounding of step 2's encoding cancels where it changes nothing),
   and the image is encoded as 8-bit sRGB.

`denoise` 0 skips 1-3: the exposure encoded as it is.
"""

from __future__ import annotations

import cv2
import numpy as np

WHITE_PERCENTILE = 99.9
"""The illumination is encoded relative to this percentile of its values (step 2)."""


def srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB to 8-bit sRGB."""
    x = np.clip(linear, 0, 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (s * 255 + 0.5).astype(np.uint8)


def linear(srgb: np.ndarray) -> np.ndarray:
    """8-bit sRGB to linear RGB in [0, 1] (`srgb8`'s inverse, up to the rounding)."""
    x = srgb.astype(np.float32) / 255
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def noise_sigma(image: np.ndarray) -> float:
    """The standard deviation of an image's white noise, in its own units: Donoho's
    estimator, the median absolute finest diagonal (Haar) wavelet coefficient / 0.6745,
    averaged over the channels. Robust to edges and texture, which are sparse in that band."""
    x = np.asarray(image, np.float32)
    x = x[: x.shape[0] // 2 * 2, : x.shape[1] // 2 * 2]
    hh = (x[0::2, 0::2] - x[0::2, 1::2] - x[1::2, 0::2] + x[1::2, 1::2]) / 2
    hh = hh.reshape(hh.shape[0] * hh.shape[1], -1)
    return float(np.mean(np.median(np.abs(hh), axis=0) / 0.6745))


def develop(radiance: np.ndarray, albedo: np.ndarray, denoise: float) -> np.ndarray:
    """The 8-bit sRGB image of an exposure (linear RGB radiance and its albedo, both
    (H, W, 3)), denoised with strength `denoise` (module docstring)."""
    if denoise <= 0:
        return srgb8(radiance)
    textured = albedo > 1e-3
    light = np.where(textured, radiance / np.maximum(albedo, 1e-3), radiance)
    white = max(float(np.percentile(light, WHITE_PERCENTILE)), 1e-6)
    encoded = srgb8(light / white)
    h = denoise * noise_sigma(encoded)
    if h <= 0:  # no noise measured
        return srgb8(radiance)
    smooth = cv2.fastNlMeansDenoisingColored(encoded, None, h, h, 7, 21)
    change = (linear(smooth) - linear(encoded)) * white
    return srgb8(radiance + np.where(textured, albedo * change, change))
