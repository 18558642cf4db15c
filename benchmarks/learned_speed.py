"""Seconds per image of ALIKED and DISK detection (the candidate pool as `bench run
--detector aliked|disk` builds it: on a copy downscaled to detector.learned_max_edge, up
to detector.learned_keypoints keypoints) and per pair of LightGlue matching (each image's
K highest-scoring keypoints), at each image size, on a synthetic textured image and its
warp by a known homography (the share of matches that agree with it is printed as a
check). On the GPU where torch sees one, else on the CPU with --threads threads. Best of
--repeats after one untimed call (loading the networks is not timed).

    .venv/bin/python benchmarks/learned_speed.py [--sizes 640x480,3072x2048] [--keypoints 1024]
        [--repeats 2] [--threads 1]

Measured at 7e46112 on the 2-core machine (CPU, one thread, under nice beside another
job; best of 1): ALIKED 1.24 s per 640x480 image (3,956 keypoints), 4.82 s per 3072x2048
one (4,096); DISK 1.67 and 4.02 s (2,961; 4,096); LightGlue 0.23-0.33 s per pair at
K = 1,024 at either size, 3.05 s (ALIKED, K = 3,956) and 2.25 s (DISK, K = 2,961) on the
whole 640x480 pools. Every match agreed with the homography.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from bench.frontend import learned
from bench.frontend.features import DetectorConfig

H = np.array([[0.95, -0.12, 0.04], [0.1, 0.97, -0.02], [0.0, 0.0, 1.0]])
"""The warp, in units of the image's width (x) and height (y)."""


def textured(width: int, height: int) -> np.ndarray:
    """An RGB image of blobs at three scales."""
    rng = np.random.default_rng(0)
    img = sum(
        cv2.resize(rng.random((height // k, width // k, 3)), (width, height), cv2.INTER_CUBIC)
        for k in (4, 16, 64)
    )
    return (255 * (img - img.min()) / np.ptp(img)).astype(np.uint8)


def homography(width: int, height: int) -> np.ndarray:
    S = np.diag([width, height, 1.0])
    return S @ H @ np.linalg.inv(S)


def best_of(repeats: int, fn, *args):
    """(the least disturbed seconds of `repeats` calls after an untimed one, the result)."""
    out, best = fn(*args), np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - t)
    return best, out


def measure(size: tuple[int, int], detector: str, keypoints: int, repeats: int) -> str:
    w, h = size
    Hp = homography(w, h)
    img = textured(w, h)
    warped = cv2.warpPerspective(img, Hp, (w, h))
    cfg = DetectorConfig(detector=detector)
    det_s, a = best_of(repeats, learned.detect, img, cfg)
    b = learned.detect(warped, cfg)
    sides = [(p[0][:keypoints], p[4][:keypoints], (w, h)) for p in (a, b)]
    match_s, m = best_of(repeats, learned.lightglue_matches, detector, *sides)
    p = np.c_[a[0][m[:, 0]], np.ones(len(m))] @ Hp.T
    agree = np.mean(np.hypot(*(p[:, :2] / p[:, 2:] - b[0][m[:, 1]]).T) < 3 * w / 640)
    return (
        f"{f'{w}x{h}':<10} {detector:<7} {det_s:9.2f} {len(a[0]):6d} {match_s:12.2f} "
        f"{min(keypoints, len(a[0])):5d} {len(m):7d} {agree:6.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="640x480,3072x2048", help="WxH,WxH")
    ap.add_argument("--keypoints", type=int, default=1024, help="K, per image, for LightGlue")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--threads", type=int, default=1, help="torch's CPU threads")
    a = ap.parse_args()
    learned.require()
    import torch

    torch.set_num_threads(a.threads)
    print(f"device {learned.device()}, {a.threads} CPU thread(s), torch {torch.__version__}")
    print("size       network  detect s  kpts  lightglue s     K matches agree")
    for size in a.sizes.split(","):
        w, h = map(int, size.split("x"))
        for detector in learned.LEARNED:
            print(measure((w, h), detector, a.keypoints, a.repeats), flush=True)


if __name__ == "__main__":
    main()
