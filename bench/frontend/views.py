"""What a real front end sees: the images and the calibration. Nothing else.

Three sources give the same list of `View`s:

* a render entry (`renders/<scene>-s<seed>-<key>/`): its images and its COLMAP rig;
* a dataset, `DIR/images/` and a model of a registered format (`bench.frontend.formats`:
  COLMAP's, binary or text, in `DIR/sparse/0/` or `DIR/sparse/`): the views of the model,
  posed;
* a folder of images without poses (`bench select`, `bench frontend`): every image in it
  (`IMAGE_SUFFIXES`; the other files are named in one log line), with a camera from a
  model when one is given (of a registered format), else from the focal-length prior
  (EXIF's 35 mm equivalent focal length, or COLMAP's default 1.2 x max(width, height), a
  guess: `View.focal_known` False, and the front end estimates it from the images,
  `bench.frontend.geometry.estimate_focal`).

An image is read whole or refused: a file OpenCV cannot decode, and a JPEG that ends
before its end-of-image marker (OpenCV would return its decoded part), are refused in one
line naming the file and why (empty, not an image format's signature, or a header whose
data cannot be decoded).

This module is the front end's and back end's only way into the data; it never opens
ground-truth files.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from bench import BenchError
from bench.camera import Camera
from bench.console import log
from bench.files import (
    META,
    checksum,
    content_key,
    entry_problem,
    read_meta,
    views_pixels,
)
from bench.frontend.colmap_model import check_images
from bench.frontend.formats import DatasetFormat, find_model, format_of, layouts, read_cameras

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")
"""The image files a folder's views are read from (those OpenCV decodes)."""
DEFAULT_FOCAL_FACTOR = 1.2
"""COLMAP's focal-length prior without EXIF: 1.2 x max(width, height)."""


class ImageFile:
    """An image file, decoded on its first use and kept (the copies of a view share it)."""

    def __init__(self, path: Path, width: int, height: int):
        self._path, self._size = Path(path), (width, height)
        self._pixels: np.ndarray | None = None

    def __call__(self) -> np.ndarray:
        if self._pixels is None:
            img = read_image(self._path)
            if img.shape[1::-1] != self._size:
                raise BenchError(
                    f"{self._path} is {img.shape[1]}x{img.shape[0]}, its camera says "
                    f"{self._size[0]}x{self._size[1]}"
                )
            self._pixels = img
        return self._pixels


@dataclass(frozen=True)
class View:
    """One calibrated image."""

    index: int
    name: str
    """File name relative to the image folder (the name COLMAP records)."""
    pixels: np.ndarray | ImageFile
    """The image (`image`), or its file, decoded when first needed."""
    camera: Camera
    posed: bool = True
    """Whether `camera` holds a real pose (False: intrinsics only, identity pose)."""
    focal_known: bool = True
    """Whether the focal length is known (a model, EXIF); False: COLMAP's default guess."""

    @property
    def image(self) -> np.ndarray:
        """8-bit sRGB, HxWx3 (RGB order)."""
        return self.pixels() if isinstance(self.pixels, ImageFile) else self.pixels

    @property
    def gray(self) -> np.ndarray:
        return cv2.cvtColor(self.image, cv2.COLOR_RGB2GRAY)

    def scale_to(self, max_size: int) -> tuple[View, float, float]:
        """The view downscaled so that its longer side is at most `max_size` px (itself
        when it is no larger), and the scale factors (sx, sy) from this view to it."""
        c = self.camera
        s = max_size / max(c.width, c.height)
        if s >= 1:
            return self, 1.0, 1.0
        w, h = max(1, round(c.width * s)), max(1, round(c.height * s))
        sx, sy = w / c.width, h / c.height
        img = cv2.resize(self.image, (w, h), interpolation=cv2.INTER_AREA)
        cam = Camera(w, h, c.fx * sx, c.fy * sy, c.cx * sx, c.cy * sy, c.R, c.t)
        return replace(self, pixels=img, camera=cam), sx, sy

    def without_pose(self) -> View:
        """The same image and intrinsics with the pose removed (identity, `posed` False):
        what a task that grants no poses hands to the front end."""
        c = self.camera
        cam = Camera(c.width, c.height, c.fx, c.fy, c.cx, c.cy, np.eye(3), np.zeros(3))
        return replace(self, camera=cam, posed=False)


@dataclass(frozen=True)
class Source:
    """Where a set of views lives: the image folder, and the model that poses them."""

    images: Path
    model: Path
    format: DatasetFormat
    """The model's format (`bench.frontend.formats`)."""
    dataset: bool = False
    """A dataset's folder: the model must pose exactly the images in `images`."""

    def cameras(self) -> list[tuple[str, Camera]]:
        """(image name, camera) of every image the model poses, in name order."""
        return self.format.read(self.model)

    def seen(self) -> dict[str, np.ndarray]:
        """The ids of the model's points each image observes, by image name (none for a
        model without points)."""
        return self.format.seen(self.model)

    @staticmethod
    def kind(path: Path) -> str:
        """'render' for a render entry (a cache entry: it has a record, `files.META`), else
        'dataset': the one place that tells them apart."""
        return "render" if (Path(path) / META).is_file() else "dataset"

    @staticmethod
    def of(path: Path) -> Source:
        """A render entry (its COLMAP rig), or a dataset folder: `images/` and a model of a
        registered format where that format keeps it (`bench.frontend.formats`)."""
        path = Path(path)
        if Source.kind(path) == "render":
            problem = entry_problem(path)
            if problem:
                raise BenchError(f"render entry {path} is not usable: {problem}")
            return Source(path, path, format_of(path))
        found = find_model(path)
        if (path / "images").is_dir() and found is not None:
            fmt, model = found
            return Source(path / "images", model, fmt, dataset=True)
        raise BenchError(f"{path} is neither a render entry nor a dataset: images/ and {layouts()}")


def images_alone(path: Path) -> bool:
    """Whether `path` is a folder of images alone (`load_image_folder`'s): neither a render
    entry nor a folder with `images/`, which is a dataset's (`Source.of`)."""
    return Source.kind(path) != "render" and not (Path(path) / "images").is_dir()


def source_key(path: Path) -> str:
    """What a set of views is, by content: a render entry's name (its key hashes what made
    its pixels); for a dataset, a hash of its model and every image (not its folder's
    name), so a dataset whose contents change is computed again; for a folder of images
    alone (`images_alone`), a hash of its images."""
    path, alone = Path(path), images_alone(path)
    if alone:
        files = [path / name for name in image_files(path)]
    else:
        src = Source.of(path)
        if Source.kind(path) == "render":
            return path.name
        files = sorted(p for p in src.model.iterdir() if p.is_file())
        files += sorted(p for p in src.images.rglob("*") if p.is_file())
    stats = tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files)
    return f"{'images' if alone else 'dataset'}-{_contents_key(path, stats)}"


def pixels_key(path: Path) -> str:
    """What the images of a set of views are, by content: for a render entry the hash of
    its views' decoded pixels (`image_pixels_key`, recorded in its meta as it is made; the
    reference set's are its manifest's), for a dataset or a folder of images its
    `source_key` (its files' contents). Two rows with the same `pixels` read the same
    images, on any machine."""
    path = Path(path)
    if Source.kind(path) == "render":
        return read_meta(path).get("pixels") or views_pixels(sorted(path.glob("view_*.png")))
    return source_key(path)


@cache
def _contents_key(root: Path, stats: tuple) -> str:
    """Hash of the files' contents (memoised while their sizes and times stay the same)."""
    return content_key(
        [(Path(f).relative_to(root).as_posix(), checksum(f)) for f, _, _ in stats], 8
    )


def truncated_jpeg(data: bytes) -> bool:
    """Whether JPEG bytes end before the end-of-image marker (FFD9) of their last scan
    (FFDA): inside entropy-coded data an FF byte is always stuffed, so neither marker can
    appear there."""
    return data[:2] == b"\xff\xd8" and data.rfind(b"\xff\xd9") < data.rfind(b"\xff\xda")


def read_image(path: Path) -> np.ndarray:
    """An image as 8-bit RGB, pixels as stored (EXIF orientation ignored, as COLMAP does);
    a file not read whole is refused (module docstring)."""
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise BenchError(f"cannot read image {path}: {e.strerror}") from None
    if truncated_jpeg(data):
        raise BenchError(
            f"cannot read image {path}: the JPEG is truncated (no end-of-image marker)"
        )
    flags = cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION
    level = cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:  # the reason is ours, in one line, not OpenCV's warning
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags) if data else None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None:
        raise BenchError(f"{path} is not a readable image: {_undecodable(data)}")
    return img[..., ::-1].copy()


SIGNATURES = {
    "PNG": (b"\x89PNG\r\n\x1a\n",),
    "JPEG": (b"\xff\xd8\xff",),
    "TIFF": (b"II*\x00", b"MM\x00*"),
    "WebP": (b"RIFF",),
}
"""The first bytes of each format OpenCV reads for a folder's views (`IMAGE_SUFFIXES`)."""


def _undecodable(data: bytes) -> str:
    """Why OpenCV could not decode an image file's bytes, in a few words."""
    if not data:
        return "the file is empty"
    kind = next((k for k, sigs in SIGNATURES.items() if data.startswith(sigs)), None)
    if kind is None:
        *first, last = SIGNATURES
        names = f"{', '.join(first)} or {last}"
        return f"its first bytes ({data[:8]!r}) are the signature of no {names} file"
    return f"its {kind} header is followed by data that cannot be decoded (damaged or cut short)"


def exif_focal(path: Path, width: int, height: int) -> float | None:
    """Focal length in pixels from EXIF's 35 mm equivalent, or None without it."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            f35 = im.getexif().get_ifd(0x8769).get(0xA405)
    except (OSError, UnidentifiedImageError, ValueError):  # no EXIF PIL can read
        return None
    return float(f35) / 36.0 * max(width, height) if f35 else None


def load_views(source: Path | Source) -> list[View]:
    """The calibrated, posed views of a render entry or a dataset (see the module docstring);
    each image is decoded when first needed."""
    src = source if isinstance(source, Source) else Source.of(source)
    model = src.cameras()
    if src.dataset:
        check_images([n for n, _ in model], image_files(src.images), src.model, src.images)
    return [
        View(i, name, ImageFile(src.images / name, cam.width, cam.height), cam)
        for i, (name, cam) in enumerate(model)
    ]


def folder_files(folder: Path) -> tuple[list[str], list[str]]:
    """The image files (`IMAGE_SUFFIXES`) of a folder and its other files (recursively),
    as sorted relative names."""
    folder = Path(folder)
    if not folder.is_dir():
        raise BenchError(f"image folder {folder} does not exist")
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    images = [f for f in files if Path(f).suffix.lower() in IMAGE_SUFFIXES]
    return images, [f for f in files if f not in set(images)]


def image_files(folder: Path) -> list[str]:
    """The image files of a folder (recursively), as sorted relative names."""
    return folder_files(folder)[0]


def _posed_views(folder: Path, model: Path) -> list[View]:
    """The views of the folder's images that the model poses; the model's images that the
    folder lacks, and the folder's images it does not pose, are counted in a line each."""
    present = set(image_files(folder))
    posed = read_cameras(model)
    absent = [n for n, _ in posed if n not in present]
    if absent:
        log(
            f"the model in {model} poses {len(absent)} image(s) besides the "
            f"{len(posed) - len(absent)} in {folder} (first: {absent[0]}); using those present"
        )
    unposed = sorted(present - {n for n, _ in posed})
    if unposed:
        log(
            f"{folder}: {len(unposed)} image(s) the model in {model} does not pose are left "
            f"out (first: {unposed[0]})"
        )
    kept = [(n, cam) for n, cam in posed if n in present]
    return [
        View(i, name, ImageFile(folder / name, cam.width, cam.height), cam)
        for i, (name, cam) in enumerate(kept)
    ]


def load_image_folder(folder: Path, model: Path | None = None) -> list[View]:
    """Every image of a folder: posed from a model when one is given (the images
    both hold, `_posed_views`), else unposed with the focal-length prior; the files it
    skips are named. At least two images."""
    folder = Path(folder)
    if model is not None:
        views = _posed_views(folder, Path(model))
    else:
        names, skipped = folder_files(folder)
        if skipped:
            log(
                f"{folder}: skipped {len(skipped)} file(s) that are not images "
                f"({'/'.join(IMAGE_SUFFIXES)}): {', '.join(skipped[:20])}"
                + (f" and {len(skipped) - 20} more" if len(skipped) > 20 else "")
            )
        views = []
        for i, name in enumerate(names):
            img = read_image(folder / name)
            h, w = img.shape[:2]
            f = exif_focal(folder / name, w, h)
            known = f is not None
            f = f if known else DEFAULT_FOCAL_FACTOR * max(w, h)
            cam = Camera(w, h, f, f, w / 2, h / 2, np.eye(3), np.zeros(3))
            views.append(View(i, name, img, cam, posed=False, focal_known=known))
    if len(views) < 2:
        raise BenchError(f"{folder} holds {len(views)} usable image(s); at least two are needed")
    return views
