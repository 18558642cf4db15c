"""Tentative matches on the GPU (torch), exactly the CPU's (`bench.frontend.features.
tentative_matches`): mutual nearest neighbours of unit float descriptors (SIFT's) that
pass Lowe's ratio test.

Both sides compute a squared distance as 2 - 2 a.b in FP32 (TF32 off on the GPU), but
their dot products sum in different orders, so their last bits may differ. Each differs
from the exact value by at most `D2_BOUND` (a 128-term FP32 dot product of unit vectors
errs by at most 128 u / (1 - 128 u) in any order, u = 2^-24; doubled, plus the rounding
of 2 - 2 a.b), so the two by at most twice that. Every decision is therefore checked
against that margin: each row's nearest neighbour against its second, the nearest row of
each matched column against its second, and the ratio test at both ends of the margin.
Where a decision is that close, the pair is matched on the CPU instead; otherwise the GPU's
decisions are the CPU's, and so are the matches. Any other descriptor (binary, not unit
length, fewer than 2 per side) is matched on the CPU. No GPU (or no torch): `None`,
without importing torch.
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

import numpy as np

U = 2.0**-24
"""The unit roundoff of FP32."""
UNIT_ATOL = 1e-4
"""The tolerance `descriptor_distances` takes descriptors as unit length with."""


def d2_bound(dim: int) -> float:
    """The most one FP32 squared distance 2 - 2 a.b of unit descriptors of `dim` entries
    can err by, in any summation order: 2 gamma_dim |a||b| (with the norms at most 1 +
    `UNIT_ATOL`) plus the rounding of the subtraction from 2 (half an ulp of 4)."""
    gamma = dim * U / (1 - dim * U)
    return 2 * gamma * (1 + UNIT_ATOL) ** 2 + 2 * U * 4


@cache
def device():
    """The CUDA device where one is present and torch is installed, else None (torch is
    not imported on a machine without an NVIDIA driver)."""
    if not Path("/proc/driver/nvidia").exists() or importlib.util.find_spec("torch") is None:
        return None
    import torch

    if not torch.cuda.is_available():
        return None
    torch.backends.cuda.matmul.allow_tf32 = False
    return torch.device("cuda")


MIN_DESCRIPTORS = 2048
"""The fewest descriptors on each side for which the GPU is asked at all. Measured on a
lent H100 (`benchmarks/gpu_match_check.py`, two sparse entries, ms per pair, CPU against
GPU): B = 128 0.20 / 0.99, 256 0.57 / 1.36, 512 2.37 / 2.95, whole pools 29.4 / 24.2; and
a slice at B = 256 on 16 workers spent 11 times its one-worker matching seconds with
every worker on the GPU (97 against 8.7 s): a budget's matching stays on the CPU."""


def ratio_matches(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float) -> np.ndarray | None:
    """The CPU's tentative matches of two views, computed on the GPU; None where there is
    no GPU, fewer than `MIN_DESCRIPTORS` on a side, or the CPU must decide (module
    docstring)."""
    where = device()
    if where is None or min(len(desc_a), len(desc_b)) < MIN_DESCRIPTORS:
        return None
    return matches_on(desc_a, desc_b, ratio, where)


def _unit(desc: np.ndarray) -> bool:
    return desc.dtype == np.float32 and np.allclose((desc * desc).sum(1), 1, atol=UNIT_ATOL)


def matches_on(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float, where) -> np.ndarray | None:
    """`ratio_matches` on a given torch device (the tests use the CPU's)."""
    import torch

    if len(desc_a) < 2 or len(desc_b) < 2 or not (_unit(desc_a) and _unit(desc_b)):
        return None
    a = torch.from_numpy(desc_a).to(where)
    b = torch.from_numpy(desc_b).to(where)
    d2 = torch.mm(a, b.T).mul_(-2).add_(2).clamp_(min=0)
    m = 2 * d2_bound(desc_a.shape[1])  # the most the CPU's and this squared distance differ
    two, nn_ab = d2.topk(2, dim=1, largest=False)
    col_two, nn_ba = d2.topk(2, dim=0, largest=False)
    rows = torch.arange(len(a), device=where)
    mutual = nn_ba[0, nn_ab[:, 0]] == rows
    d1, d2nd = two[:, 0].double(), two[:, 1].double()
    slack = 1 + 8 * U  # the FP32 roundings of both square roots, of ratio and of ratio * d
    # the CPU's ratio test, d1 < ratio * d2 (distances), sure at both ends of the margin
    sure_pass = (d1 + m).sqrt() * slack < ratio * (d2nd - m).clamp(min=0).sqrt()
    sure_fail = (d1 - m).clamp(min=0).sqrt() > ratio * (d2nd + m).sqrt() * slack
    row_clear = (d2nd - d1) > m  # the nearest column is the CPU's too
    col_gap = (col_two[1] - col_two[0]).double() > m
    col_clear = col_gap[nn_ab[:, 0]]  # the nearest row of the matched column is the CPU's
    # a row the ratio test surely fails is dropped on both sides whatever its neighbours
    # (the two smallest distances move by at most the margin, whichever columns they are)
    decided = sure_fail | (sure_pass & row_clear & col_clear)
    if not bool(decided.all()):
        return None
    keep = mutual & sure_pass
    a_idx = rows[keep]
    return torch.stack([a_idx, nn_ab[keep, 0]], 1).cpu().numpy().astype(np.int64)


def describe() -> str:
    """Where tentative matches are computed, for a run's log."""
    return "GPU (torch, exact)" if device() is not None else "CPU"
