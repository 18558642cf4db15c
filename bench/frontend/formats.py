"""The formats of a dataset's model: the one registry through which a dataset folder is
recognised (`bench.frontend.views.Source.of`) and its cameras and poses are read.

A dataset is a folder with its images in `images/` and a model that poses them. A format
is the function that reads its model, registered with `@dataset_format(name, recognise,
what, places=..., seen=...)`: `read(folder)` returns (image name, `Camera`) for every
image the model poses; `recognise(folder)` says whether a folder holds such a model;
`what` names it in a few words (the error for a folder that is no dataset lists them);
`places` are where in a dataset folder the model is looked for, in order; `seen(folder)`,
if the model has points, the ids of those each image observes (co-visibility, for a
dataset's bags and its truth; without it, from the poses alone). The first format
registered that recognises a folder is its format: COLMAP's binary model, then its text
model (`bench.frontend.colmap_model`), are the first two (pycolmap reads the binary one
where both are there).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench import BenchError
from bench.camera import Camera
from bench.frontend import colmap_model

Reader = Callable[[Path], list[tuple[str, Camera]]]


def _no_points(folder: Path) -> dict[str, np.ndarray]:
    """A model without points: no image observes any."""
    return {}


@dataclass(frozen=True)
class DatasetFormat:
    """A registered format of a dataset's model (module docstring)."""

    name: str
    read: Reader
    recognise: Callable[[Path], bool]
    what: str
    places: tuple[str, ...]
    seen: Callable[[Path], dict[str, np.ndarray]] = _no_points


FORMATS: dict[str, DatasetFormat] = {}
"""Every format, in the order registered (the order they are tried in)."""


def dataset_format(
    name: str,
    recognise: Callable[[Path], bool],
    what: str,
    places: tuple[str, ...] = ("sparse/0", "sparse"),
    seen: Callable[[Path], dict[str, np.ndarray]] = _no_points,
) -> Callable[[Reader], Reader]:
    """Register the decorated reader as format `name` (module docstring)."""

    def register(read: Reader) -> Reader:
        FORMATS[name] = DatasetFormat(name, read, recognise, what, tuple(places), seen)
        return read

    return register


def format_of(folder: Path) -> DatasetFormat | None:
    """The format of the model in `folder`, or None where no format recognises it."""
    return next((f for f in FORMATS.values() if f.recognise(Path(folder))), None)


def find_model(dataset: Path) -> tuple[DatasetFormat, Path] | None:
    """A dataset's model and its format: the first of the formats' places (in the order
    the formats are registered) that holds one; None where none does."""
    for fmt in FORMATS.values():
        for place in fmt.places:
            folder = Path(dataset) / place
            if folder.is_dir() and fmt.recognise(folder):
                return fmt, folder
    return None


def read_cameras(folder: Path) -> list[tuple[str, Camera]]:
    """(image name, camera) of every image the model in `folder` poses, by its format."""
    fmt = format_of(folder)
    if fmt is None:
        kinds = " or ".join(f.what for f in FORMATS.values())
        raise BenchError(f"{folder} holds no model ({kinds})")
    return fmt.read(Path(folder))


def layouts() -> str:
    """Where a dataset holds a model of each format, in a line."""
    return "; or ".join(
        f"{f.what} in {' or '.join(p + '/' for p in f.places)}" for f in FORMATS.values()
    )


def _colmap(ext: str) -> Callable[[Path], bool]:
    return lambda folder: colmap_model.holds(folder, ext)


dataset_format(
    "colmap-binary",
    _colmap("bin"),
    "a COLMAP binary model (cameras.bin, images.bin)",
    seen=colmap_model.points_seen,
)(colmap_model.read_model)
dataset_format(
    "colmap-text",
    _colmap("txt"),
    "a COLMAP text model (cameras.txt, images.txt)",
    seen=colmap_model.points_seen,
)(colmap_model.read_model)
