"""Triangle-mesh primitives in numpy: (vertices, faces, uv) triples that can be merged."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Geom(NamedTuple):
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray


def quad(origin, u, v, uv_repeat=(1.0, 1.0)) -> Geom:
    """Parallelogram with corners origin, +u, +u+v, +v; its normal is u x v."""
    o, u, v = (np.asarray(a, float) for a in (origin, u, v))
    V = np.stack([o, o + u, o + u + v, o + v])
    UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * uv_repeat
    return Geom(V, np.array([[0, 1, 2], [0, 2, 3]]), UV)


def box(center, size, yaw: float = 0.0) -> Geom:
    """Axis-aligned box (then turned by `yaw` about z); each face maps the whole texture."""
    sx, sy, sz = np.asarray(size, float) / 2
    faces = [  # origin, u, v with u x v pointing outward
        ((-sx, -sy, -sz), (0, 2 * sy, 0), (2 * sx, 0, 0)),  # bottom
        ((-sx, -sy, sz), (2 * sx, 0, 0), (0, 2 * sy, 0)),  # top
        ((-sx, -sy, -sz), (2 * sx, 0, 0), (0, 0, 2 * sz)),  # front (-y)
        ((sx, sy, -sz), (-2 * sx, 0, 0), (0, 0, 2 * sz)),  # back (+y)
        ((-sx, sy, -sz), (0, -2 * sy, 0), (0, 0, 2 * sz)),  # left (-x)
        ((sx, -sy, -sz), (0, 2 * sy, 0), (0, 0, 2 * sz)),  # right (+x)
    ]
    return place(merge([quad(*f) for f in faces]), center, yaw)


def cylinder(base, radius: float, height: float, segments: int = 48) -> Geom:
    """Closed upright cylinder standing on `base`; the side wraps the texture once."""
    a = np.linspace(0, 2 * np.pi, segments + 1)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], 1)
    V = np.concatenate([ring, ring + [0, 0, height]])
    n = segments + 1
    i = np.arange(segments)
    F = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    UV = np.concatenate(
        [np.stack([a / (2 * np.pi), np.zeros(n)], 1), np.stack([a / (2 * np.pi), np.ones(n)], 1)]
    )
    side = Geom(V, F, UV)
    caps = [disk(radius, z, up) for z, up in ((0.0, False), (height, True))]
    return place(merge([side, *caps]), base)


def disk(radius: float, z: float, up: bool, segments: int = 48) -> Geom:
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    V = np.concatenate(
        [[[0, 0, z]], np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, z)], 1)]
    )
    i = np.arange(segments)
    F = np.stack([np.zeros_like(i), 1 + i, 1 + (i + 1) % segments], 1)
    F = F if up else F[:, ::-1]
    return Geom(V, F, 0.5 + 0.5 * V[:, :2] / radius)


def sphere(center, radius: float, n_u: int = 48, n_v: int = 24) -> Geom:
    """UV sphere; the texture wraps once around and pole to pole."""
    u, v = np.meshgrid(np.linspace(0, 1, n_u + 1), np.linspace(0, 1, n_v + 1))
    th, ph = 2 * np.pi * u, np.pi * v
    V = radius * np.stack([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), -np.cos(ph)], -1)
    idx = np.arange((n_u + 1) * (n_v + 1)).reshape(n_v + 1, n_u + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    F = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return place(Geom(V.reshape(-1, 3), F, np.stack([u, v], -1).reshape(-1, 2)), center)


def tube(p0, p1, radius: float, segments: int = 8) -> Geom:
    """Open cylinder (a branch) from p0 to p1."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = p1 - p0
    a = axis / np.linalg.norm(axis)
    e1 = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    ang = np.linspace(0, 2 * np.pi, segments + 1)
    ring = radius * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    V = np.concatenate([p0 + ring, p1 + ring])
    n, i = segments + 1, np.arange(segments)
    F = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    UV = np.concatenate(
        [
            np.stack([ang / (2 * np.pi), np.zeros(n)], 1),
            np.stack([ang / (2 * np.pi), np.ones(n)], 1),
        ]
    )
    return Geom(V, F, UV)


def leaf(center, direction, normal, length: float, width: float) -> Geom:
    """A flat pointed leaf (six-sided fan) centred at `center`, its tip along `direction`."""
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    s = np.cross(np.asarray(normal, float), d)
    s /= np.linalg.norm(s)
    prof = np.array([[-0.5, 0], [-0.25, 0.4], [0.15, 0.5], [0.5, 0], [0.15, -0.5], [-0.25, -0.4]])
    V = np.asarray(center, float) + length * prof[:, :1] * d + width * prof[:, 1:] * s
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    return Geom(V, F, np.stack([prof[:, 0] + 0.5, prof[:, 1] + 0.5], 1))


def flipped(g: Geom) -> Geom:
    """The same surface with its normals reversed (e.g. a dome seen from inside)."""
    return Geom(g.vertices, g.faces[:, ::-1], g.uv)


def place(g: Geom, offset, yaw: float = 0.0) -> Geom:
    """Turn by `yaw` radians about z, then move by `offset`."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return Geom(g.vertices @ R.T + np.asarray(offset, float), g.faces, g.uv)


def merge(geoms: list[Geom]) -> Geom:
    """One mesh from many (renderers are much faster with few large meshes)."""
    offsets = np.cumsum([0] + [len(g.vertices) for g in geoms[:-1]])
    return Geom(
        np.concatenate([g.vertices for g in geoms]).astype(np.float32),
        np.concatenate([g.faces + o for g, o in zip(geoms, offsets)]).astype(np.int32),
        np.concatenate([g.uv for g in geoms]).astype(np.float32),
    )
