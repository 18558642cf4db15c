"""A contact sheet of every scene's views, so a person can see the scenes at a glance."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bench.files import atomic_path
from bench.render.entry import entry_meta, image_name


def write_gallery(entries: dict[str, Path], out: Path, thumb_width: int = 320) -> Path:
    """One row per scene (its name on the first thumbnail), one column per view."""
    rows = []
    for name, entry in entries.items():
        thumbs = []
        for v in range(len(entry_meta(entry)["cameras"])):
            img = cv2.imread(str(entry / image_name(v)))
            h = round(img.shape[0] * thumb_width / img.shape[1])
            thumbs.append(cv2.resize(img, (thumb_width, h), interpolation=cv2.INTER_AREA))
        cv2.putText(thumbs[0], name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (0, 0, 0), 4)
        cv2.putText(thumbs[0], name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (255, 255, 255), 2)
        rows.append(np.concatenate(thumbs, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        cv2.imwrite(str(tmp), np.concatenate(rows, 0))
    return out
