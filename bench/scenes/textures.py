"""Procedural textures in numpy: float32 HxWx3 linear albedo in [0, 1], row 0 is v = 0."""

from __future__ import annotations

import cv2
import numpy as np


def _shape(size: int | tuple[int, int]) -> tuple[int, int]:
    return (size, size) if isinstance(size, int) else size


def noise(
    rng: np.random.Generator, size: int | tuple[int, int], scales=(4, 16, 64), weights=None
) -> np.ndarray:
    """Grey value noise in [0, 1] of `size` (square, or (height, width)): random grids of
    the given cell counts along the shorter side, smoothly upsampled."""
    h, w = _shape(size)
    weights = weights or [1.0 / (i + 1) for i in range(len(scales))]
    out = np.zeros((h, w), np.float32)
    for cells, wt in zip(scales, weights):
        grid = rng.random((max(1, cells * h // min(h, w)), max(1, cells * w // min(h, w))))
        out += wt * cv2.resize(grid.astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    out -= out.min()
    return out / max(float(out.max()), 1e-6)


def fractal(rng: np.random.Generator, size: int | tuple[int, int], coarsest: int = 2) -> np.ndarray:
    """Grey noise with equal contrast in every octave from `coarsest` cells (along the
    shorter side) to two texels a cell: the 1/f amplitude spectrum of natural images, so
    there is detail at every scale a detector looks at, not only at the coarse scales
    `noise` stops at."""
    octaves = int(np.log2(min(_shape(size)) // 2 // coarsest)) + 1
    scales = tuple(coarsest * 2**k for k in range(octaves))
    return noise(rng, size, scales, [1.0] * octaves)


def tint(gray: np.ndarray, dark, light) -> np.ndarray:
    """Map grey [0, 1] linearly between two colours."""
    dark, light = np.asarray(dark, np.float32), np.asarray(light, np.float32)
    return (dark + gray[..., None] * (light - dark)).astype(np.float32)


def contrast(tex: np.ndarray, amount: float) -> np.ndarray:
    """Scale the texture's deviation from its mean colour by `amount`."""
    mean = tex.reshape(-1, 3).mean(0)
    return np.clip(mean + amount * (tex - mean), 0, 1).astype(np.float32)


def checker(size: int, n: int, c0, c1) -> np.ndarray:
    i = (np.arange(size) * n // size)[:, None] + (np.arange(size) * n // size)[None, :]
    return np.where((i % 2 == 0)[..., None], np.float32(c0), np.float32(c1)).astype(np.float32)


def _to_u8(img: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8))


def _color(rng: np.random.Generator, lo: float, hi: float) -> tuple[int, int, int]:
    return tuple(int(v) for v in rng.uniform(lo, hi, 3) * 255)


def label(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """A packaging label: coloured background, random words, a bar code and a logo disc."""
    bg = rng.uniform(0.3, 0.9, 3).astype(np.float32)
    img = _to_u8(bg * (0.85 + 0.15 * noise(rng, size, (8, 32))[..., None]))
    ink = _color(rng, 0, 0.25)
    for row in range(4):
        word = "".join(rng.choice(list("ABCDEFGHKMNPRSTUVWXYZ0123456789"), rng.integers(3, 7)))
        y = int(size * (0.18 + 0.16 * row))
        cv2.putText(img, word, (int(size * 0.06), y), cv2.FONT_HERSHEY_SIMPLEX, size / 320, ink, 2)
    x0, w = size * 0.08, size * 0.84 / 40
    for k in np.flatnonzero(rng.integers(0, 2, 40)):
        p0, p1 = (int(x0 + k * w), int(size * 0.78)), (int(x0 + (k + 1) * w), int(size * 0.94))
        cv2.rectangle(img, p0, p1, ink, -1)
    cv2.circle(img, (int(size * 0.8), int(size * 0.25)), int(size * 0.1), _color(rng, 0.1, 1), -1)
    return img.astype(np.float32) / 255


def speckle(
    rng: np.random.Generator, size: int | tuple[int, int], count: int, palette=None
) -> np.ndarray:
    """Random dots and strokes over noise: dense, non-repeating detail. Colours are drawn at
    random, or from `palette` (a list of RGB triples) with jitter."""
    h, w = _shape(size)
    img = _to_u8(tint(noise(rng, (h, w), (8, 32, 128)), (0.25, 0.25, 0.25), (0.75, 0.75, 0.75)))
    side = min(h, w)
    for _ in range(count):
        if palette is None:
            c = _color(rng, 0, 1)
        else:
            base = np.asarray(palette[rng.integers(len(palette))]) * rng.uniform(0.7, 1.3)
            c = tuple(int(v) for v in np.clip(base, 0, 1) * 255)
        p = tuple(int(v) for v in rng.integers(0, (w, h)))
        if rng.random() < 0.5:
            cv2.circle(img, p, int(rng.integers(2, side // 24)), c, -1)
        else:
            q = tuple(int(v) for v in np.asarray(p) + rng.integers(-side // 10, side // 10, 2))
            cv2.line(img, p, q, c, int(rng.integers(1, 4)))
    return img.astype(np.float32) / 255


def bricks(
    rng: np.random.Generator, size: int = 512, rows: int = 8, cols: int = 4, mortar=0.75
) -> np.ndarray:
    """Running-bond brick wall: `rows` x `cols` bricks per texture tile, mortar lines, jitter."""
    img = np.empty((size, size, 3), np.float32)
    img[:] = mortar
    bh, bw = size // rows, size // cols
    base = np.array([0.55, 0.27, 0.18])
    for r in range(rows):
        off = (bw // 2) * (r % 2)
        for c in range(-1, cols + 1):
            x0, x1 = c * bw + off + 3, (c + 1) * bw + off - 3
            color = np.clip(base * rng.uniform(0.85, 1.15) + rng.normal(0, 0.02, 3), 0, 1)
            img[r * bh + 3 : (r + 1) * bh - 3, max(x0, 0) : max(min(x1, size), 0)] = color
    return img * (0.85 + 0.15 * noise(rng, size, (16, 64, 256))[..., None])


def tiles(
    rng: np.random.Generator, size: int | tuple[int, int], cell: int, c0, c1, grout=0.03
) -> np.ndarray:
    """Square tiles of `cell` texels and jittered colour between c0 and c1, grout lines."""
    h, w = _shape(size)
    t = rng.random((-(-h // cell), -(-w // cell))).astype(np.float32)
    img = tint(np.kron(t, np.ones((cell, cell), np.float32))[:h, :w], c0, c1)
    g = max(1, int(grout * cell))
    img[np.arange(h) % cell < g] *= 0.7
    img[:, np.arange(w) % cell < g] *= 0.7
    return img * (0.9 + 0.1 * noise(rng, (h, w), (8, 64))[..., None])


def window(size: int = 256) -> np.ndarray:
    """A glazed window with mullions: identical for every window of a facade."""
    y, x = np.mgrid[0:size, 0:size] / size
    img = np.empty((size, size, 3), np.float32)
    img[:] = tint(0.5 + 0.5 * (y - x), (0.08, 0.12, 0.18), (0.35, 0.45, 0.55))
    bar = (
        (np.abs(x - 0.5) < 0.03)
        | (np.abs(y - 0.55) < 0.03)
        | (np.minimum.reduce([x, y, 1 - x, 1 - y]) < 0.06)
    )
    img[bar] = (0.85, 0.85, 0.82)
    return img


def leaf(rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """Green leaf with a light midrib and veins."""
    base = rng.uniform([0.05, 0.2, 0.02], [0.15, 0.45, 0.08])
    img = _to_u8(tint(noise(rng, size, (4, 16, 64)), base * 0.6, base * 1.4))
    vein = tuple(int(v) for v in np.clip(base * 2.2, 0, 1) * 255)
    cv2.line(img, (0, size // 2), (size, size // 2), vein, 3)
    for k in range(1, 6):
        x = k * size // 6
        cv2.line(img, (x, size // 2), (x + size // 8, 0), vein, 1)
        cv2.line(img, (x, size // 2), (x + size // 8, size), vein, 1)
    return img.astype(np.float32) / 255
