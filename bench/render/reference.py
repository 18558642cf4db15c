"""The reference renders: every view the default grid reads, as fixed data under a SHA-256
manifest, so that every machine reads the same pixels.

Renders differ in their last bits between machines (the LLVM backend compiles for the
host's vector width with fast math, Embree picks its instruction set per machine, image
blocks add atomically; CUDA differs again), so rows computed from two machines' renders
are not comparable. The reference set is rendered once and shipped in `reference/`:
- `images/<scene>-s<seed>/u<i>-<n>.webp`: the view at path position i/n (lowest terms),
  lossless WebP (docs/scenes.md, "The reference renders": the format was measured);
- `renders.json`, the manifest: what made them (renderer, variant, versions, machine, the render
  settings and code hash), each file's SHA-256 and decoded pixels' hash, and for each
  rig (scene, seed, views) its render key, its files in view order and its `pixels`.

`bench run` reads a rig from the reference set whenever the set holds it under the
current render key (`reference_key`) and no variant was asked for by name: the entry
(`renders/reference/<scene>-s<seed>-<key>/`) gets the shipped views, checked against the
manifest (a missing or altered file is named and refused), and ground truth recomputed
here by the AOV pass alone (`bench.render.mitsuba.truth_view`: about a fifth of a path
trace; it can differ from the reference machine's truth in a few pixels' last bits, which
scoring tolerates, docs/scenes.md). `bench render` and a named `--variant` render anew.
`write_reference` rebuilds the set from rendered entries (`scripts/build_reference.py`,
after a scene or the render code changed).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from bench import ROOT, BenchError, files
from bench.render.config import RenderConfig
from bench.scenes.catalog import path_positions

REFERENCE = ROOT / "reference"
MANIFEST = "renders.json"
SUBFOLDER = "reference"
"""Where the entries made from the reference set live in a renders folder (their names
are a local render's; the `pixels` in their meta tell them apart)."""
WEBP_LOSSLESS = [cv2.IMWRITE_WEBP_QUALITY, 101]
"""OpenCV's WebP quality above 100: lossless."""


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def rig_name(scene: str, seed: int, views: int) -> str:
    return f"{scene}-s{seed}-v{views}"


def image_file(scene: str, seed: int, u: Fraction) -> str:
    return f"images/{scene}-s{seed}/u{u.numerator}-{u.denominator}.webp"


def read_manifest(root: Path | None = None) -> dict | None:
    """The reference set's manifest (None where there is no set)."""
    root = Path(root or REFERENCE)
    try:
        return json.loads((Path(root) / MANIFEST).read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        raise BenchError(f"{Path(root) / MANIFEST} is unreadable ({e}); restore it from git") from e


def reference_rig(scene: str, seed: int, cfg: RenderConfig, key: str, root: Path | None = None):
    """The manifest's record of (scene, seed, views) when the set holds it under render key
    `key` (the scene's code, parameters and the settings unchanged), else None."""
    manifest = read_manifest(root)
    if manifest is None or cfg.variant != "auto":
        return None
    rig = manifest["rigs"].get(rig_name(scene, seed, cfg.views))
    return rig if rig is not None and rig["render_key"] == key else None


def reference_variant(root: Path | None = None) -> str | None:
    """The variant the reference set was rendered with (its render keys name it)."""
    manifest = read_manifest(root)
    return manifest["made_by"]["variant"] if manifest else None


def checked_files(rig: dict, root: Path | None = None) -> list[tuple[Path, dict]]:
    """A rig's shipped files, each checked against the manifest's SHA-256 (a missing or
    altered one is one `BenchError` naming it and the remedy), with what the manifest says
    of it. Cheap: every use of a reference entry's cached copy checks its source this way,
    so the repository's own data cannot rot unseen behind a cache."""
    root = Path(root or REFERENCE)
    manifest, out = read_manifest(root), []
    for name in rig["images"]:
        path, want = Path(root) / name, manifest["images"][name]
        if not path.is_file():
            raise BenchError(
                f"reference render {path} is missing; restore it with `git checkout -- {path}`"
            )
        got = sha256(path)
        if got != want["sha256"]:
            raise BenchError(
                f"reference render {path} is altered (SHA-256 {got[:12]}, the manifest says "
                f"{want['sha256'][:12]}); restore it with `git checkout -- {path}`"
            )
        out.append((path, want))
    return out


def checked_images(rig: dict, root: Path | None = None) -> list[np.ndarray]:
    """A rig's shipped views, decoded, each file checked against the manifest's SHA-256
    (`checked_files`) and pixel hash: a missing or altered file is one `BenchError`."""
    out = []
    for path, want in checked_files(rig, root):
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None or files.image_pixels_key(image) != want["pixels"]:
            raise BenchError(f"reference render {path} does not decode to its manifest's pixels")
        out.append(image)
    return out


def machine() -> dict:
    """What rendered: the processor, its cores, the system."""
    model = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.partition(":")[2].strip()
                break
    except OSError:
        pass
    return {"processor": model, "cores": os.cpu_count(), "system": platform.platform()}


def write_reference(rigs: list[dict], root: Path | None = None) -> dict:
    """The reference set from rendered rigs (`bench.render.entry.reference_input`: scene,
    seed, views, render key, decoded views, what made them, seconds per view), all made
    alike: every view once, as lossless WebP, and the manifest; a file already there is
    kept when its pixels are the same. Returns the manifest."""
    root = Path(root or REFERENCE)
    manifest = {"made_by": None, "images": {}, "rigs": {}}
    for rig in rigs:
        made_by = rig["made_by"] | {"machine": machine()}
        if manifest["made_by"] not in (None, made_by):
            raise BenchError(
                f"{rig_name(rig['scene'], rig['seed'], rig['views'])} was made "
                f"otherwise than the other rigs: {made_by}"
            )
        manifest["made_by"] = made_by
        names, keys = [], []
        for v, (u, image) in enumerate(zip(path_positions(rig["views"]), rig["images"])):
            name, key = image_file(rig["scene"], rig["seed"], u), files.image_pixels_key(image)
            path = root / name
            if manifest["images"].get(name, {}).get("pixels", key) != key:
                raise BenchError(
                    f"{rig['scene']} seed {rig['seed']}: view {v} of "
                    f"{rig['views']} differs from another rig's at {name}"
                )
            if not path.is_file() or files.image_pixels_key(cv2.imread(str(path))) != key:
                path.parent.mkdir(parents=True, exist_ok=True)
                _, data = cv2.imencode(".webp", image, WEBP_LOSSLESS)
                with files.atomic_path(path) as tmp:
                    tmp.write_bytes(data.tobytes())
            manifest["images"][name] = {"sha256": sha256(path), "pixels": key}
            names.append(name)
            keys.append(key)
        manifest["rigs"][rig_name(rig["scene"], rig["seed"], rig["views"])] = {
            **{k: rig[k] for k in ("scene", "seed", "views", "render_key")},
            "images": names,
            "pixels": files.images_pixels_key(keys),
            "seconds_per_view": rig["seconds_per_view"],
        }
    manifest["images"] = dict(sorted(manifest["images"].items()))
    manifest["rigs"] = dict(sorted(manifest["rigs"].items()))
    files.write_text_atomic(root / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    return manifest
