"""Reading the ground-truth layers of a render entry. Imported only by the evaluation."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench import BenchError


@dataclass(frozen=True)
class GroundTruth:
    """One view's ground truth (float32 HxW or HxWx3; NaN / -1 where nothing was hit)."""

    range: np.ndarray
    z: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    shape_index: np.ndarray

    @property
    def single_surface(self) -> np.ndarray:
        """Pixels covered by one surface (an integral shape index): their layers are exact,
        while pixels on an occlusion edge average two surfaces."""
        return (self.shape_index >= 0) & (self.shape_index == np.round(self.shape_index))


def load_ground_truth(entry: Path) -> list[GroundTruth]:
    entry = Path(entry)
    try:
        n = len(json.loads((entry / "meta.json").read_text())["cameras"])
        out = []
        for v in range(n):
            with np.load(entry / f"gt_{v:02d}.npz") as z:
                out.append(
                    GroundTruth(
                        *(z[k] for k in ("range", "z", "position", "normal", "shape_index"))
                    )
                )
        return out
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as e:
        raise BenchError(f"cannot read the ground truth of {entry}: {e}") from e
