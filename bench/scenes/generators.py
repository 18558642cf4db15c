"""The procedural scene types. Each builder turns its `scenes/<name>.toml` parameters and
a seeded generator into meshes, a sun (or None) and the rig: `views` cameras on the scene's
camera path (documented in its `scenes/<name>.toml` description)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

import bench.scenes.shapes as shapes
import bench.scenes.textures as textures
from bench.camera import Camera, look_at
from bench.scenes.shapes import Geom
from bench.scenes.spec import Material, Mesh, generator


def path_positions(views: int) -> list[Fraction]:
    """The position of each of `views` cameras on its scene's path, 0 to 1 evenly, exact:
    a rig of 21 views holds a rig of 6 at the same positions."""
    return [Fraction(i, max(views - 1, 1)) for i in range(views)]


def _mesh(name: str, g: Geom, material: Material, motion=None) -> Mesh:
    return Mesh(
        name,
        g.vertices.astype(np.float32),
        g.faces.astype(np.int32),
        g.uv.astype(np.float32),
        material,
        motion,
    )


def _arc_rig(
    p: dict, target, width: int, height: int, views: int, start_deg: float = -90.0
) -> list[Camera]:
    """`views` cameras evenly on an arc of `arc_deg` around `target`, centred at `start_deg`."""
    az = np.radians([start_deg + p["arc_deg"] * (float(u) - 0.5) for u in path_positions(views)])
    tx, ty, _ = target
    eyes = [
        (tx + p["radius"] * np.cos(a), ty + p["radius"] * np.sin(a), p["cam_height"]) for a in az
    ]
    return [look_at(e, target, width=width, height=height, fov_x_deg=p["fov_deg"]) for e in eyes]


def _room(rng, size: float, height: float, light: float, wall_tex, floor_tex) -> list[Mesh]:
    """Floor, four walls, ceiling and a ceiling light panel, all facing inward."""
    h, s = height, size / 2
    walls = shapes.merge(
        [
            shapes.quad((-s, -s, 0), (2 * s, 0, 0), (0, 0, h), (4, 1)),
            shapes.quad((s, s, 0), (-2 * s, 0, 0), (0, 0, h), (4, 1)),
            shapes.quad((-s, s, 0), (0, -2 * s, 0), (0, 0, h), (4, 1)),
            shapes.quad((s, -s, 0), (0, 2 * s, 0), (0, 0, h), (4, 1)),
        ]
    )
    ls = size / 4
    return [
        _mesh(
            "floor",
            shapes.quad((-s, -s, 0), (2 * s, 0, 0), (0, 2 * s, 0), (6, 6)),
            Material(floor_tex),
        ),
        _mesh("walls", walls, Material(wall_tex)),
        _mesh(
            "ceiling",
            shapes.quad((-s, -s, h), (0, 2 * s, 0), (2 * s, 0, 0)),
            Material(color=(0.8, 0.8, 0.8)),
        ),
        _mesh(
            "ceiling_light",
            shapes.quad((-ls / 2, -ls / 2, h - 0.01), (0, ls, 0), (ls, 0, 0)),
            Material(color=(0.8, 0.8, 0.8), emission=(light, light, light * 0.95)),
        ),
    ]


@generator("table")
def table(p: dict, rng: np.random.Generator, width: int, height: int, views: int):
    top_z = 1.5
    wall = textures.tint(textures.noise(rng, 256, (4, 16)), (0.55, 0.52, 0.48), (0.65, 0.62, 0.58))
    floor = textures.tint(
        textures.noise(rng, 256, (2, 8, 64)), (0.25, 0.18, 0.12), (0.45, 0.33, 0.22)
    )
    meshes = _room(rng, 16.0, 7.0, p["light"], wall, floor)
    wood = textures.tint(
        textures.noise(rng, 512, (3, 12, 96, 256)), (0.35, 0.2, 0.1), (0.6, 0.4, 0.22)
    )
    legs = [
        shapes.box((x, y, top_z / 2), (0.15, 0.15, top_z)) for x in (-2.3, 2.3) for y in (-1.4, 1.4)
    ]
    frame = shapes.merge([shapes.box((0, 0, top_z - 0.05), (5.0, 3.2, 0.1)), *legs])
    meshes.append(_mesh("table", frame, Material(wood)))

    placed: list[tuple[float, float, float]] = []
    while len(placed) < p["n_objects"]:
        r = rng.uniform(0.25, 0.5)
        x, y = rng.uniform(-2.5 + r, 2.5 - r), rng.uniform(-1.6 + r, 1.6 - r)
        if any(np.hypot(x - a, y - b) < r + c + 0.05 for a, b, c in placed):
            continue
        placed.append((x, y, r))
    for k, (x, y, r) in enumerate(placed):
        kind = ("box", "cylinder", "sphere")[k % 3]
        if kind == "box":
            hgt = rng.uniform(0.4, 1.1)
            g = shapes.box(
                (x, y, top_z + hgt / 2), (1.3 * r, 1.3 * r, hgt), yaw=rng.uniform(0, np.pi)
            )
            tex = textures.label(rng)
        elif kind == "cylinder":
            g = shapes.cylinder((x, y, top_z), 0.8 * r, rng.uniform(0.5, 1.2))
            c0, c1 = rng.uniform(0, 0.3, 3), rng.uniform(0.6, 1.0, 3)
            tex = textures.checker(256, int(rng.integers(6, 12)), c0, c1)
        else:
            g = shapes.sphere((x, y, top_z + r), r)
            tex = textures.speckle(rng, 256, 120)
        meshes.append(
            _mesh(
                f"object_{k:02d}_{kind}", g, Material(textures.contrast(tex, p["texture_contrast"]))
            )
        )
    rig = _arc_rig(p, (0.0, 0.0, 1.9), width, height, views)
    return meshes, rig, None


def _sky_dome(radius: float, radiance: float) -> Mesh:
    """A large inward-facing emitting sphere: every ray hits geometry, so ground truth is total."""
    g = shapes.flipped(shapes.sphere((0, 0, 0), radius, 32, 16))
    return _mesh(
        "sky", g, Material(color=(0, 0, 0), emission=(0.75 * radiance, 0.85 * radiance, radiance))
    )


def _sun(irradiance: float, direction) -> dict:
    d = np.asarray(direction, float)
    return {
        "direction": tuple(d / np.linalg.norm(d)),
        "irradiance": (irradiance, 0.95 * irradiance, 0.85 * irradiance),
    }


@generator("corridor")
def corridor(p: dict, rng: np.random.Generator, width: int, height: int, views: int):
    L, W, H, c = p["length"], p["width"], p["ceiling"], p["texture_contrast"]
    y0, y1 = -W / 2, W / 2

    # painted plaster, tiles and ceiling boards with detail at every scale (`fractal`), each
    # one texture over its whole surface (texels of 6.35 mm), so that only the tile grid
    # and the fittings repeat; the plaster has its own contrast (`paint_contrast`): with too
    # little, a forward pair's matches lie on the floor alone, and a pair on one plane
    # does not tell its relative pose (COLMAP classes it planar)
    def px(metres: float) -> int:
        return int(round(metres / 0.00635))

    paint = textures.contrast(
        textures.tint(textures.fractal(rng, (px(H), px(L))), (0.45, 0.47, 0.45), (0.9, 0.9, 0.86)),
        c * p["paint_contrast"],
    )
    floor = textures.tiles(rng, (px(W), px(L)), px(0.3), (0.35, 0.33, 0.3), (0.5, 0.47, 0.43))
    chips = [(0.3, 0.28, 0.25), (0.55, 0.52, 0.47), (0.2, 0.2, 0.2)]  # terrazzo
    chips = textures.speckle(rng, floor.shape[:2], int(floor.size / 3 / 175), chips)
    floor = textures.contrast(floor * chips * 1.6, c)
    ceil = textures.tiles(rng, (px(L), px(W)), px(0.6), (0.75, 0.75, 0.75), (0.85, 0.85, 0.85))
    ceil = textures.contrast(
        ceil * (0.7 + 0.6 * textures.fractal(rng, ceil.shape[:2])[..., None]), c
    )
    meshes = [
        _mesh("floor", shapes.quad((0, y0, 0), (L, 0, 0), (0, W, 0)), Material(floor)),
        _mesh("ceiling", shapes.quad((0, y0, H), (0, W, 0), (L, 0, 0)), Material(ceil)),
        _mesh(
            "walls",
            shapes.merge(
                [
                    shapes.quad((0, y1, 0), (L, 0, 0), (0, 0, H)),
                    shapes.quad((0, y0, 0), (L, 0, 0), (0, 0, H)),
                    shapes.quad((L, y0, 0), (0, W, 0), (0, 0, H), (W / L, 1)),
                    shapes.quad((0, y0, 0), (0, W, 0), (0, 0, H), (W / L, 1)),
                ]
            ),
            Material(paint),
        ),
    ]
    panels = [
        shapes.quad((x, -0.3, H - 0.01), (0, 0.6, 0), (1.2, 0, 0))
        for x in np.arange(2.0, L - 1, 3.0)
    ]
    meshes.append(
        _mesh(
            "ceiling_lights",
            shapes.merge(panels),
            Material(color=(0.9, 0.9, 0.9), emission=(p["light"],) * 3),
        )
    )
    skirting = [shapes.box((L / 2, y, 0.06), (L, 0.04, 0.12)) for y in (y0 + 0.02, y1 - 0.02)]
    meshes.append(_mesh("skirting", shapes.merge(skirting), Material(color=(0.3, 0.28, 0.25))))
    frames, doors = [], []
    for k, x in enumerate(np.linspace(5.0, L - 3.0, int(p["n_doors"]))):
        side = 1 if k % 2 else -1
        yw = side * (W / 2 - 0.05)
        frames += [shapes.box((x + dx, yw, 1.05), (0.1, 0.1, 2.1)) for dx in (-0.55, 0.55)]
        frames.append(shapes.box((x, yw, 2.15), (1.2, 0.1, 0.1)))
        doors.append(shapes.box((x, side * (W / 2 - 0.02), 1.05), (1.0, 0.04, 2.1)))
    meshes.append(_mesh("door_frames", shapes.merge(frames), Material(color=(0.7, 0.7, 0.68))))
    wood = textures.contrast(
        textures.tint(textures.fractal(rng, 256), (0.4, 0.3, 0.22), (0.55, 0.42, 0.3)), c
    )
    meshes.append(_mesh("doors", shapes.merge(doors), Material(wood)))
    for k in range(int(p["n_posters"])):
        x, side = rng.uniform(4.0, L - 4.0), 1 if rng.random() < 0.5 else -1
        w, h = rng.uniform(0.6, 1.0), rng.uniform(0.8, 1.2)
        yw = side * (W / 2 - 0.01)
        g = shapes.quad((x - w / 2 * side, yw, 1.0), (w * side, 0, 0), (0, 0, h))
        meshes.append(_mesh(f"poster_{k}", g, Material(textures.label(rng))))
    # forward along the corridor, weaving from side to side, every camera looking at the
    # far end; positions are functions of the path position u, so that a rig of more views
    # holds a rig of fewer on the same path; points near the far end have little parallax
    rig, target = [], (L, 0.0, 0.95 * p["cam_height"])
    for u in map(float, path_positions(views)):
        x = p["start"] + u * p["travel"]
        eye = (x, p["sway"] * np.cos(2 * np.pi * p["weaves"] * u), p["cam_height"])
        rig.append(look_at(eye, target, width=width, height=height, fov_x_deg=p["fov_deg"]))
    return meshes, rig, None


@generator("facade")
def facade(p: dict, rng: np.random.Generator, width: int, height: int, views: int):
    cols, floors, per, rec, c = (
        int(p["columns"]),
        int(p["floors"]),
        p["period"],
        p["recess"],
        p["texture_contrast"],
    )
    floor_h, win_w, win_h, sill_z = 3.2, 0.5 * p["period"], 1.6, 0.9
    x0, x1 = -cols * per / 2 - 1.0, cols * per / 2 + 1.0
    top = floors * floor_h + 0.8
    wins = [
        (-cols * per / 2 + (i + 0.5) * per - win_w / 2, f * floor_h + sill_z)
        for f in range(floors)
        for i in range(cols)
    ]
    xs = sorted({x0, x1, *[w[0] for w in wins], *[w[0] + win_w for w in wins]})
    zs = sorted({0.0, top, *[w[1] for w in wins], *[w[1] + win_h for w in wins]})
    holes = {(round(wx, 6), round(wz, 6)) for wx, wz in wins}
    wall = [
        shapes.quad((a, 0, b), (a2 - a, 0, 0), (0, 0, b2 - b))
        for a, a2 in zip(xs, xs[1:])
        for b, b2 in zip(zs, zs[1:])
        if (round(a, 6), round(b, 6)) not in holes
    ]
    wall = shapes.merge(wall)
    wall = wall._replace(uv=wall.vertices[:, [0, 2]] / 2.0)  # bricks tile every 2 units
    brick = textures.contrast(textures.bricks(rng), c)
    meshes = [_mesh("wall", wall, Material(brick))]
    reveals, panes, frames, sills = [], [], [], []
    for wx, wz in wins:
        reveals += [
            shapes.quad((wx, 0, wz), (win_w, 0, 0), (0, rec, 0)),
            shapes.quad((wx, rec, wz + win_h), (win_w, 0, 0), (0, -rec, 0)),
            shapes.quad((wx, 0, wz), (0, rec, 0), (0, 0, win_h)),
            shapes.quad((wx + win_w, rec, wz), (0, -rec, 0), (0, 0, win_h)),
        ]
        panes.append(shapes.quad((wx, rec, wz), (win_w, 0, 0), (0, 0, win_h)))
        cx = wx + win_w / 2
        frames += [shapes.box((cx, -0.03, wz + win_h + 0.05), (win_w + 0.2, 0.06, 0.1))]
        frames += [
            shapes.box((wx + dx, -0.03, wz + win_h / 2), (0.1, 0.06, win_h))
            for dx in (-0.05, win_w + 0.05)
        ]
        sills.append(shapes.box((cx, -p["ledge"] / 2, wz - 0.05), (win_w + 0.3, p["ledge"], 0.1)))
    for f in range(1, floors + 1):
        sills.append(
            shapes.box(
                ((x0 + x1) / 2, -0.6 * p["ledge"] / 2, f * floor_h - 0.1),
                (x1 - x0, 0.6 * p["ledge"], 0.18),
            )
        )
    stone = textures.contrast(
        textures.tint(textures.noise(rng, 256, (8, 32, 128)), (0.55, 0.53, 0.5), (0.75, 0.73, 0.7)),
        c,
    )
    meshes += [
        _mesh("window_reveals", shapes.merge(reveals), Material(color=(0.6, 0.58, 0.55))),
        _mesh("window_panes", shapes.merge(panes), Material(textures.window())),
        _mesh("window_frames", shapes.merge(frames), Material(color=(0.9, 0.9, 0.88))),
        _mesh("ledges", shapes.merge(sills), Material(stone)),
    ]
    paving = textures.contrast(
        textures.tiles(rng, 512, 128, (0.35, 0.35, 0.36), (0.6, 0.58, 0.55)), c
    )
    meshes.append(
        _mesh(
            "pavement",
            shapes.quad((-40, -30, 0), (80, 0, 0), (0, 30, 0), (80 / 2.4, 30 / 2.4)),
            Material(paving),
        )
    )
    meshes.append(_sky_dome(90.0, p["sky"]))
    D = p["street_distance"]
    rig = []
    for t in (2 * float(u) - 1 for u in path_positions(views)):
        eye = (t * p["span"] / 2, -D, p["cam_height"])
        yaw = np.radians(p["yaw_deg"]) * -t
        rig.append(
            look_at(
                eye,
                (eye[0] + D * np.tan(yaw), 0.0, p["target_height"]),
                width=width,
                height=height,
                fov_x_deg=p["fov_deg"],
            )
        )
    return meshes, rig, _sun(p["sun"], (0.35, 0.6, -0.7))


@generator("vegetation")
def vegetation(p: dict, rng: np.random.Generator, width: int, height: int, views: int):
    c = p["texture_contrast"]
    earth = [(0.35, 0.25, 0.15), (0.2, 0.15, 0.1), (0.5, 0.45, 0.35), (0.25, 0.35, 0.12)]
    soil = textures.speckle(rng, 1024, 2400, earth) * np.float32([0.9, 0.8, 0.6])
    soil = textures.contrast(soil, c)
    meshes = [
        _mesh(
            "ground", shapes.quad((-40, -40, 0), (80, 0, 0), (0, 80, 0), (10, 10)), Material(soil)
        )
    ]
    branches, leaves = [], [[] for _ in range(3)]
    for _ in range(int(p["n_plants"])):
        base = np.array([rng.uniform(-3.5, 3.5), rng.uniform(-2.0, 2.0), 0.0])
        hgt = rng.uniform(1.2, 2.2)
        branches.append(shapes.tube(base, base + [0, 0, hgt], 0.04))
        tips = []
        for _b in range(6):
            start = base + [0, 0, rng.uniform(0.3, 0.8) * hgt]
            d = np.array([*rng.normal(0, 1, 2), rng.uniform(0.3, 1.0)])
            tip = start + rng.uniform(0.4, 0.9) * d / np.linalg.norm(d)
            branches.append(shapes.tube(start, tip, 0.02))
            tips.append(tip)
        tips.append(base + [0, 0, hgt])
        for _k in range(int(p["leaves_per_plant"])):
            center = tips[rng.integers(len(tips))] + rng.normal(0, 0.25, 3)
            d, n = rng.normal(0, 1, 3), rng.normal(0, 1, 3)
            n -= d * (n @ d) / (d @ d)
            size = p["leaf_size"] * rng.uniform(0.7, 1.3)
            leaves[rng.integers(3)].append(shapes.leaf(center, d, n, size, 0.45 * size))
    bark = textures.tint(textures.noise(rng, 128, (4, 32)), (0.2, 0.13, 0.08), (0.4, 0.28, 0.18))
    meshes.append(_mesh("branches", shapes.merge(branches), Material(bark)))
    wind = int(rng.integers(2**63))
    for k, group in enumerate(leaves):
        g = shapes.merge(group)
        # each view's gust is drawn from its position on the path, u = i / (views - 1) in
        # lowest terms, so that a rig of more views on the same path holds the same leaves
        # where it holds the same cameras
        per_leaf = np.stack(
            [
                np.random.default_rng([wind, k, u.numerator, u.denominator]).normal(
                    0, p["wind"], (len(group), 3)
                )
                for u in path_positions(views)
            ]
        )
        motion = np.repeat(per_leaf, len(group[0].vertices), axis=1).astype(
            np.float32
        )  # six vertices a leaf
        meshes.append(
            _mesh(f"leaves_{k}", g, Material(textures.contrast(textures.leaf(rng), c)), motion)
        )
    meshes.append(_sky_dome(90.0, p["sky"]))
    return (
        meshes,
        _arc_rig(p, (0.0, 0.0, 0.8), width, height, views),
        _sun(p["sun"], (0.3, 0.5, -0.8)),
    )
