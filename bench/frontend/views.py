"""What a real front end sees of a render entry: the images and the calibration. Nothing else.

This module is the front end's and back end's only way into `renders/`; it never opens
the ground-truth files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from bench import BenchError
from bench.camera import Camera, read_colmap_rig
from bench.files import entry_problem


@dataclass(frozen=True)
class View:
    """One calibrated image."""

    index: int
    image: np.ndarray
    """8-bit sRGB, HxWx3 (RGB order)."""
    camera: Camera

    @property
    def gray(self) -> np.ndarray:
        return cv2.cvtColor(self.image, cv2.COLOR_RGB2GRAY)


def load_views(entry: Path) -> list[View]:
    """The six calibrated views of a render entry (a damaged entry is a `BenchError`)."""
    entry = Path(entry)
    problem = entry_problem(entry)
    if problem:
        raise BenchError(f"render entry {entry} is not usable: {problem}")
    cams = read_colmap_rig(entry)
    views = []
    for i, cam in enumerate(cams):
        img = cv2.imread(str(entry / f"view_{i:02d}.png"), cv2.IMREAD_COLOR)
        if img is None:
            raise BenchError(f"cannot read {entry / f'view_{i:02d}.png'}")
        views.append(View(i, img[..., ::-1].copy(), cam))
    return views
