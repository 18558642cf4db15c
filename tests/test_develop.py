"""Developing an exposure into the camera's image: the noise estimate and the denoiser of
the light, on hand-made exposures with known noise and texture."""

from __future__ import annotations

import numpy as np
import pytest

from bench.render.develop import develop, noise_sigma, srgb8


def _noisy(sigma: float, seed: int = 0) -> np.ndarray:
    """A smooth ramp with sharp squares on it (edges the estimate must not count), plus
    white noise of `sigma`."""
    y, x = np.mgrid[0:240, 0:320].astype(np.float32)
    clean = 60 + 0.3 * x + 0.2 * y
    clean[(x // 40 + y // 40) % 2 == 0] += 80
    return clean + np.random.default_rng(seed).normal(0, sigma, clean.shape)


@pytest.mark.parametrize("sigma", [0.0, 1.0, 3.0, 8.0])
def test_noise_sigma_measures_white_noise_beside_edges(sigma):
    assert noise_sigma(_noisy(sigma)) == pytest.approx(sigma, abs=0.08 + 0.05 * sigma)
    three = np.stack([_noisy(sigma, s) for s in range(3)], axis=-1)
    assert noise_sigma(three) == pytest.approx(sigma, abs=0.08 + 0.05 * sigma)


def _exposure(sigma: float):
    """A striped texture (albedo) under smooth light with a hard shadow, the light noisy
    by `sigma` (relative): (radiance, albedo, clean radiance)."""
    y, x = np.mgrid[0:120, 0:160].astype(np.float32)
    stripes = np.where((x // 3) % 2 == 0, 0.7, 0.25)
    albedo = np.repeat(stripes[..., None], 3, axis=-1).astype(np.float32)
    light = (0.4 + 0.4 * x / 160) * np.where(y < 60, 1.0, 0.35)
    noise = np.random.default_rng(1).normal(0, sigma, light.shape) * light
    clean = albedo * light[..., None]
    return albedo * (light + noise)[..., None], albedo, clean


def test_develop_removes_the_lights_noise_and_keeps_the_texture():
    radiance, albedo, clean = _exposure(0.08)
    truth = srgb8(clean).astype(float)
    raw = np.abs(srgb8(radiance) - truth).mean()
    done = develop(radiance, albedo, 3.0)
    assert np.abs(done - truth).mean() < raw / 3  # the noise goes
    # the texture stays: every stripe edge keeps its contrast (columns 3k-1 | 3k)
    row = done[30:50, :, 1].astype(float).mean(axis=0)
    edges = np.abs(np.diff(row))[2::3][:-1]
    assert edges.min() > 0.8 * np.abs(np.diff(truth[30:50, :, 1].mean(axis=0)))[2::3][:-1].min()


def test_develop_off_is_the_encoded_exposure_and_a_clean_one_is_left_alone():
    radiance, albedo, clean = _exposure(0.08)
    np.testing.assert_array_equal(develop(radiance, albedo, 0.0), srgb8(radiance))
    # no noise measured, nothing to remove: at most a rounding step anywhere
    assert np.abs(develop(clean, albedo, 3.0).astype(int) - srgb8(clean)).max() <= 1
