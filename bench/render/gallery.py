"""A contact sheet of every scene's views, so a person can see the scenes at a glance."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from bench.files import atomic_path


def write_gallery(entries: dict[str, Path], out: Path, thumb_width: int = 320) -> Path:
    """One row per scene (its name on the first thumbnail), one column per view."""
    rows = []
    for name, entry in entries.items():
        thumbs = []
        for v in range(len(json.loads((entry / "meta.json").read_text())["cameras"])):
            img = cv2.imread(str(entry / f"view_{v:02d}.png"))
            h = round(img.shape[0] * thumb_width / img.shape[1])
            thumbs.append(cv2.resize(img, (thumb_width, h), interpolation=cv2.INTER_AREA))
        cv2.putText(thumbs[0], name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (0, 0, 0), 4)
        cv2.putText(thumbs[0], name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (255, 255, 255), 2)
        rows.append(np.concatenate(thumbs, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        cv2.imwrite(str(tmp), np.concatenate(rows, 0))
    return out
