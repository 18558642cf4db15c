"""`bench export`: a render entry written as a dataset in the COLMAP layout, so that the
rendered path and `bench run --dataset` can be checked against each other.

OUT/images/ (the views), OUT/sparse/ (cameras.txt, images.txt with the ground-truth poses,
an empty points3D.txt), OUT/ground_truth/points.ply (the world positions of every
single-surface pixel of every view: the surface the rendered path measures against) and
OUT/ground_truth/<image>.npz (z, and position with NaN off single-surface pixels), and
OUT/dataset.json (where it came from).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.console import log
from bench.evaluation.layers import (
    CLOUD,
    TRUTH_DIR,
    read_layers,
    surface_samples,
    write_ply_points,
)
from bench.files import atomic_dir, locked
from bench.frontend.colmap_model import read_model
from bench.render.entry import entry_meta


def check_target(out: Path) -> None:
    """Refuse an `out` that exists and is not an earlier export (before anything renders)."""
    if Path(out).exists() and not (Path(out) / "dataset.json").is_file():
        raise BenchError(f"{out} exists and is not an earlier export; choose an empty folder")


def export_dataset(entry: Path, out: Path) -> Path:
    """Write the dataset (module docstring); an earlier export at `out` is replaced."""
    entry, out = Path(entry), Path(out)
    check_target(out)
    if out.exists():
        try:
            was = json.loads((out / "dataset.json").read_text())
            log(f"replacing the export of {was['scene']} seed {was['seed']} in {out}")
        except (OSError, ValueError, KeyError, TypeError):
            log(f"replacing the earlier export in {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    names = [n for n, _ in read_model(entry)]
    gts = read_layers(entry)
    with locked(out), atomic_dir(out) as tmp:
        for sub in ("images", "sparse", TRUTH_DIR):
            (tmp / sub).mkdir()
        for name, gt in zip(names, gts):
            shutil.copy2(entry / name, tmp / "images" / name)
            pos = np.where(gt.single_surface[..., None], gt.position, np.nan).astype(np.float32)
            np.savez_compressed(tmp / TRUTH_DIR / f"{name}.npz", z=gt.z, position=pos)
        for f in ("cameras.txt", "images.txt"):
            shutil.copy2(entry / f, tmp / "sparse" / f)
        (tmp / "sparse" / "points3D.txt").write_text(
            "# no points: the poses are the ground truth\n"
        )
        write_ply_points(tmp / TRUTH_DIR / CLOUD, surface_samples(gts))
        meta = entry_meta(entry)
        info = {"exported_from": entry.name, "scene": meta.get("scene"), "seed": meta.get("seed")}
        (tmp / "dataset.json").write_text(json.dumps(info, indent=1) + "\n")
    return out
