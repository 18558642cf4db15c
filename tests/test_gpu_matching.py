"""The GPU matcher (`bench.backend.gpu`), run here on CPU torch: exactly the CPU's
tentative matches (`bench.frontend.features.tentative_matches`) on real SIFT descriptors
of a small render, or no answer (the CPU decides); never other matches."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest

from bench.backend import gpu
from bench.frontend.features import DetectorConfig, detect, tentative_matches
from bench.frontend.views import load_views

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def pools(medium_entry):
    return [detect(v, DetectorConfig()).descriptors for v in load_views(medium_entry("table"))]


@pytest.mark.parametrize("budget", [128, 512, None])
def test_torch_matches_are_the_cpus_on_real_sift_descriptors(pools, budget):
    answered = 0
    for a, b in combinations([p[:budget] for p in pools], 2):
        out = gpu.matches_on(a, b, 0.8, torch.device("cpu"))
        if out is not None:
            answered += 1
            assert out.dtype == np.int64 and np.array_equal(out, tentative_matches(a, b, 0.8))
    assert answered >= 5  # of the 15 pairs; the others are left to the CPU, near a tie


def test_a_near_tie_is_left_to_the_cpu_and_a_clear_case_is_decided():
    rng = np.random.default_rng(0)
    a = rng.random((4, 128), np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a.copy()
    b[[0, 1]] = b[[1, 0]]  # rows 0 and 1 of a match b's 1 and 0 exactly
    out = gpu.matches_on(a, b, 0.8, torch.device("cpu"))
    assert np.array_equal(out, [[0, 1], [1, 0], [2, 2], [3, 3]])
    twin = np.vstack([b, b[:1]])  # b's column 0 twice: a's row 1 has no clear nearest
    assert gpu.matches_on(a, twin, 0.8, torch.device("cpu")) is None
    # the CPU's ratio test drops the tie (d1 = d2 = 0)
    assert np.array_equal(tentative_matches(a, twin, 0.8), [[0, 1], [2, 2], [3, 3]])


def test_binary_or_tiny_descriptors_are_left_to_the_cpu():
    bits = np.zeros((5, 32), np.uint8)
    assert gpu.matches_on(bits, bits, 0.8, torch.device("cpu")) is None
    one = np.eye(1, 128, dtype=np.float32)
    assert gpu.matches_on(one, one, 0.8, torch.device("cpu")) is None


def test_the_error_bound_covers_an_fp32_dot_product_in_any_order():
    rng = np.random.default_rng(1)
    x = rng.random((200, 128)).astype(np.float32)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    exact = 2 - 2 * (x.astype(np.float64) @ x[::-1].T.astype(np.float64))
    for order in (np.arange(128), np.arange(128)[::-1], rng.permutation(128)):
        d2 = 2 - 2 * (x[:, order] @ x[::-1, order].T)
        assert np.abs(d2 - exact).max() <= gpu.d2_bound(128)


def test_the_back_ends_matcher_gives_the_cpus_matches_with_or_without_the_device(
    pools, monkeypatch
):
    from bench.backend import matching

    a, b = pools[0][:256], pools[1][:256]
    cpu = tentative_matches(a, b, 0.8)
    assert gpu.device() is None or gpu.device().type == "cuda"
    assert np.array_equal(matching.tentative_matches(a, b, 0.8), cpu)
    seen = []
    monkeypatch.setattr(gpu, "device", lambda: seen.append(1) or torch.device("cpu"))
    assert np.array_equal(matching.tentative_matches(a, b, 0.8), cpu) and seen
