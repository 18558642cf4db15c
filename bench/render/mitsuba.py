"""The Mitsuba boundary: a scene description and an OpenCV camera to a path-traced image
with its ground-truth layers.

This is the only module that talks to Mitsuba, and `mitsuba_sensor` is the only place
where the OpenCV camera convention is converted to Mitsuba's (x left, y up, z forward).
One render per view yields the path-traced image and the ground-truth layers (an `aov`
integrator around `path`, box filter).
"""

from __future__ import annotations

import hashlib
import math
from fractions import Fraction

import numpy as np

from bench.camera import Camera
from bench.render.config import RenderConfig
from bench.render.develop import develop
from bench.scenes.catalog import path_positions
from bench.scenes.spec import Mesh, SceneDescription

MITSUBA_FROM_OPENCV = np.diag([-1.0, -1.0, 1.0])
AOVS = "dd:depth,pp:position,nn:sh_normal,si:shape_index,al:albedo"
GT_LAYERS = ("range", "z", "position", "normal", "shape_index")


def _mi():
    import mitsuba as mi

    return mi


def mitsuba_sensor(cam: Camera, spp: int) -> dict:
    """The Mitsuba perspective sensor of an OpenCV camera (centred principal point, fx = fy)."""
    if cam.fx != cam.fy or (cam.cx, cam.cy) != (cam.width / 2, cam.height / 2):
        raise ValueError("the Mitsuba sensor needs fx == fy and a centred principal point")
    to_world = np.eye(4)
    to_world[:3, :3] = cam.R.T @ MITSUBA_FROM_OPENCV
    to_world[:3, 3] = cam.center
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": math.degrees(2 * math.atan(cam.width / (2 * cam.fx))),
        "to_world": _mi().ScalarTransform4f(to_world),
        "near_clip": 0.01,
        "far_clip": 1000.0,
        "film": {
            "type": "hdrfilm",
            "width": cam.width,
            "height": cam.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
        },
        "sampler": {"type": "multijitter", "sample_count": spp},
    }


def _mitsuba_mesh(m: Mesh, view: int):
    mi = _mi()
    if m.material.texture is not None:
        albedo = {"type": "bitmap", "data": mi.TensorXf(m.material.texture), "raw": True}
    else:
        albedo = {"type": "rgb", "value": list(m.material.color)}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(
        {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": albedo}}
    )
    if m.material.emission is not None:
        props["emitter"] = mi.load_dict(
            {"type": "area", "radiance": {"type": "rgb", "value": list(m.material.emission)}}
        )
    mesh = mi.Mesh(m.name, len(m.vertices), len(m.faces), props=props, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    for key, values in (
        ("vertex_positions", m.vertices_in_view(view).astype(np.float32)),
        ("faces", m.faces.astype(np.uint32)),
        ("vertex_texcoords", m.uv.astype(np.float32)),
    ):
        params[key] = type(params[key])(np.ravel(values))  # the variant's own flat array type
    params.update()
    return mesh


def mitsuba_scene_dict(desc: SceneDescription, view: int, cfg: RenderConfig) -> dict:
    """The Mitsuba scene dictionary of one view (geometry may move between views)."""
    d = {
        "type": "scene",
        "integrator": {
            "type": "aov",
            "aovs": AOVS,
            "image": {"type": "path", "max_depth": cfg.max_depth},
        },
        "sensor": mitsuba_sensor(desc.cameras[view], cfg.spp),
    }
    for m in desc.meshes:
        d[m.name] = _mitsuba_mesh(m, view)
    if desc.sun is not None:
        d["sun"] = {
            "type": "directional",
            "direction": list(desc.sun["direction"]),
            "irradiance": {"type": "rgb", "value": list(desc.sun["irradiance"])},
        }
    return d


def split_layers(
    img: np.ndarray, cam: Camera
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Split the 14-channel AOV render into linear RGB, its albedo (what the developing
    step separates the light from, `bench.render.develop`) and the ground-truth layers."""
    if img.shape[-1] != 14:
        raise RuntimeError(f"expected 14 channels from the AOV integrator, got {img.shape[-1]}")
    hit = img[..., 3] > 0
    pos = np.where(hit[..., None], img[..., 4:7], np.nan)
    normal = img[..., 7:10]
    normal = normal / np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    gt = {
        "range": np.linalg.norm(pos - cam.center, axis=-1),
        "z": cam.to_camera(pos.reshape(-1, 3))[:, 2].reshape(pos.shape[:2]),
        "position": pos,
        "normal": np.where(hit[..., None], normal, np.nan),
        "shape_index": np.where(hit, img[..., 10], -1.0),
    }
    return img[..., :3], img[..., 11:14], {k: v.astype(np.float32) for k, v in gt.items()}


def noise_seed(seed: int, u: Fraction) -> int:
    """The sampler's seed of the view at path position `u` of scene seed `seed`: a view's
    noise is the same in every rig that holds it, whichever rendered it first."""
    digest = hashlib.sha256(f"{seed}:{u.numerator}/{u.denominator}".encode()).digest()
    return int.from_bytes(digest[:4], "little")


def expose(desc: SceneDescription, view: int, cfg: RenderConfig, variant: str):
    """Path-trace one view: (its linear RGB exposure, the albedo of the same pass, the
    ground-truth layers, the shape names by shape index)."""
    mi = _mi()
    mi.set_variant(variant)
    sc = mi.load_dict(mitsuba_scene_dict(desc, view, cfg))
    img = np.array(
        mi.render(sc, seed=noise_seed(desc.seed, path_positions(len(desc.cameras))[view]))
    )
    rgb, albedo, gt = split_layers(img, desc.cameras[view])
    return rgb, albedo, gt, [s.id() for s in sc.shapes()]


def render_view(desc: SceneDescription, view: int, cfg: RenderConfig, variant: str):
    """One view: (its 8-bit sRGB image, the exposure developed as `bench.render.develop`
    says; the ground-truth layers; the shape names by shape index)."""
    rgb, albedo, gt, names = expose(desc, view, cfg, variant)
    return develop(rgb, albedo, cfg.denoise), gt, names


def truth_view(desc: SceneDescription, view: int, cfg: RenderConfig, variant: str):
    """The ground-truth layers of one view and its shape names, without path tracing: the
    AOV integrator alone, on the same camera rays and samples (the same sampler seed), so
    the layers equal `render_view`'s on one machine to the last bit, at a fraction of the
    cost (what a reference entry's truth is made with, `bench.render.reference`)."""
    mi = _mi()
    mi.set_variant(variant)
    d = mitsuba_scene_dict(desc, view, cfg)
    d["integrator"] = {"type": "aov", "aovs": AOVS}
    sc = mi.load_dict(d)
    aovs = np.array(
        mi.render(sc, seed=noise_seed(desc.seed, path_positions(len(desc.cameras))[view]))
    )
    no_light = np.zeros((*aovs.shape[:2], 3), aovs.dtype)
    _, _, gt = split_layers(np.concatenate([no_light, aovs], axis=-1), desc.cameras[view])
    return gt, [s.id() for s in sc.shapes()]
