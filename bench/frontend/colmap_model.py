"""A COLMAP model as COLMAP writes it (`cameras`, `images`, `points3D`; text or binary),
read with pycolmap and checked before it is trusted.

pycolmap reads what it can: a text `images.txt` whose 2D-point lines are missing is read
as half the views, and a word where a number belongs is read as something. So a text model
is first checked line by line, and a damaged one is refused in one line naming the file
and the line; a binary model that pycolmap cannot read is walked record by record to name
the file and the record. The images of the model must be the images of the dataset
(`check_images`), and camera models with distortion are refused with the hint to undistort.
"""

from __future__ import annotations

import shutil
import struct
import tempfile
from functools import cache
from pathlib import Path

import numpy as np
import pycolmap

from bench import BenchError
from bench.camera import Camera

FILES = ("cameras", "images", "points3D")
_UNDISTORTED = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 4, "OPENCV": 4}
"""Camera models accepted, and how many parameters precede their distortion ones."""


def holds(folder: Path, ext: str) -> bool:
    """Whether `folder` holds a model's cameras and images in COLMAP's binary ('bin') or
    text ('txt') files."""
    return all((Path(folder) / f"{f}.{ext}").is_file() for f in FILES[:2])


def model_format(folder: Path) -> str | None:
    """'bin' or 'txt' (binary where both are there) when `folder` holds a model, else None."""
    return next((ext for ext in ("bin", "txt") if holds(folder, ext)), None)


@cache
def _num_params() -> dict[str, int]:
    """Parameters of each of COLMAP's camera models, by name."""
    out = {}
    for name, mid in pycolmap.CameraModelId.__members__.items():
        if name != "INVALID":
            out[name] = len(pycolmap.Camera.create_from_model_id(1, mid, 1.0, 1, 1).params)
    return out


def _problem(path: Path, line: int, what: str) -> BenchError:
    return BenchError(f"malformed COLMAP model: {path} line {line}: {what}")


def _numbers(tokens: list[str], kinds: str, path: Path, line: int) -> None:
    """Check that each token parses as its kind ('i' integer, 'f' number, '-' any)."""
    for tok, kind in zip(tokens, kinds):
        if kind == "-":
            continue
        try:
            int(tok) if kind == "i" else float(tok)
        except ValueError:
            word = "an integer" if kind == "i" else "a number"
            raise _problem(path, line, f"{tok!r} is not {word}") from None


def _data_lines(path: Path):
    """(line number, tokens) of every line, comments as None."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise BenchError(f"cannot read {path}: {e}") from e
    for n, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        yield n, (None if s.startswith("#") else s.split())


def check_text_model(folder: Path) -> None:
    """Refuse a damaged text model in one line (module docstring)."""
    folder = Path(folder)
    params = _num_params()
    cameras = set()
    path = folder / "cameras.txt"
    for n, tok in _data_lines(path):
        if not tok:
            continue
        if len(tok) < 4 or tok[1] not in params:
            raise _problem(path, n, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]")
        if len(tok) != 4 + params[tok[1]]:
            raise _problem(
                path, n, f"{tok[1]} has {params[tok[1]]} parameters, found {len(tok) - 4}"
            )
        _numbers(tok, "i-ii" + "f" * params[tok[1]], path, n)
        cameras.add(int(tok[0]))
    path = folder / "images.txt"
    lines, ids = iter(_data_lines(path)), set()
    for n, tok in lines:
        if not tok:
            continue
        if len(tok) < 10:
            raise _problem(path, n, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
        _numbers(tok, "ifffffffi", path, n)
        if int(tok[8]) not in cameras:
            raise _problem(path, n, f"camera {tok[8]} is not in cameras.txt")
        if int(tok[0]) in ids:
            raise _problem(path, n, f"image id {tok[0]} appears twice")
        ids.add(int(tok[0]))
        n, pts = next(lines, (n + 1, []))
        if pts is None or len(pts) % 3:
            raise _problem(
                path, n, f"expected the 2D points of image {tok[9]} (X Y POINT3D_ID triples)"
            )
        _numbers(pts, "ffi" * (len(pts) // 3), path, n)
    path = folder / "points3D.txt"
    for n, tok in _data_lines(path) if path.is_file() else ():
        if tok and (len(tok) < 8 or (len(tok) - 8) % 2):
            raise _problem(path, n, "expected POINT3D_ID X Y Z R G B ERROR TRACK[]")
        if tok:
            _numbers(tok, "ifffiiif" + "i" * (len(tok) - 8), path, n)


def _binary_problem(folder: Path) -> str | None:
    """Where a binary model stops making sense ('FILE record K: ...'), or None."""
    params = {int(pycolmap.CameraModelId.__members__[k]): v for k, v in _num_params().items()}

    def walk(name: str, record) -> str | None:
        path = folder / f"{name}.bin"
        if not path.is_file():
            return None
        data = path.read_bytes()
        if len(data) < 8:
            return f"{path}: truncated"
        (count,) = struct.unpack_from("<Q", data, 0)
        pos, done = 8, 0
        try:
            while done < count:
                pos = record(data, pos)
                done += 1
        except (struct.error, ValueError) as e:
            what = "truncated" if isinstance(e, struct.error) else str(e)
            return f"{path} record {done + 1} of {count}: {what}"
        if pos != len(data):
            return f"{path}: {len(data) - pos} bytes after the last of its {count} records"
        return None

    def camera(data, pos):
        _, model, _, _ = struct.unpack_from("<iiQQ", data, pos)
        if model not in params:
            raise ValueError(f"unknown camera model id {model}")
        struct.unpack_from(f"<{params[model]}d", data, pos + 24)
        return pos + 24 + 8 * params[model]

    def image(data, pos):
        struct.unpack_from("<I7dI", data, pos)
        end = data.find(b"\0", pos + 64)
        if end < 0:
            raise struct.error("no end of the image name")
        (n,) = struct.unpack_from("<Q", data, end + 1)
        struct.unpack_from(f"<{3 * n}d", data, end + 9)  # x, y, id: 24 bytes a point
        return end + 9 + 24 * n

    def point(data, pos):
        (n,) = struct.unpack_from("<Q3d3BdQ", data, pos)[-1:]
        struct.unpack_from(f"<{2 * n}i", data, pos + 51)
        return pos + 51 + 8 * n

    for name, record in (("cameras", camera), ("images", image), ("points3D", point)):
        where = walk(name, record)
        if where:
            return where
    return None


def read_reconstruction(folder: Path) -> pycolmap.Reconstruction:
    """The one reader of a COLMAP model in `folder` (a photo set's, a dataset's, a
    prediction's exported model): pycolmap's reading of it, binary where both are there (a
    model without points gets an empty points file). `read_model` checks it first."""
    folder = Path(folder)
    fmt = model_format(folder)
    if fmt is None:
        raise BenchError(f"{folder} holds no COLMAP model (cameras and images, .txt or .bin)")
    if (folder / f"points3D.{fmt}").is_file():
        return pycolmap.Reconstruction(str(folder))
    with tempfile.TemporaryDirectory() as tmp:
        for f in FILES[:2]:
            shutil.copyfile(folder / f"{f}.{fmt}", Path(tmp) / f"{f}.{fmt}")
        (Path(tmp) / f"points3D.{fmt}").write_bytes(b"" if fmt == "txt" else bytes(8))
        return pycolmap.Reconstruction(tmp)


def intrinsics(model: str, w: int, h: int, p: list[float], where: Path) -> tuple:
    """(width, height, fx, fy, cx, cy) of a camera without distortion; refused otherwise."""
    if model not in _UNDISTORTED or any(p[_UNDISTORTED[model] :]):
        raise BenchError(
            f"{where}: camera model {model} with distortion is not supported; undistort the "
            "images first (colmap image_undistorter)"
        )
    if model in ("PINHOLE", "OPENCV"):  # fx, fy, cx, cy
        return w, h, *p[:4]
    return w, h, p[0], p[0], p[1], p[2]  # f, cx, cy


def read_model(folder: Path) -> list[tuple[str, Camera]]:
    """(image name, camera) of every image of the model in `folder`, in name order."""
    folder = Path(folder)
    fmt = model_format(folder)
    if fmt is None:
        raise BenchError(f"{folder} holds no COLMAP model (cameras and images, .txt or .bin)")
    if fmt == "txt":
        check_text_model(folder)
    try:
        rec = read_reconstruction(folder)
    except Exception as e:  # pycolmap raises ValueError or RuntimeError
        where = _binary_problem(folder) if fmt == "bin" else None
        raise BenchError(
            f"malformed COLMAP model: {where}" if where else f"cannot read {folder}: {e}"
        ) from e
    out = []
    for image in rec.images.values():
        cam = rec.cameras[image.camera_id]
        params = [float(x) for x in cam.params]
        intr = intrinsics(cam.model.name, int(cam.width), int(cam.height), params, folder)
        pose = image.cam_from_world()
        R, t = np.asarray(pose.rotation.matrix()), np.asarray(pose.translation)
        out.append((image.name, Camera(*intr, R=R, t=t)))
    if not out:
        raise BenchError(f"the COLMAP model in {folder} has no images")
    names = [n for n, _ in out]
    if len(set(names)) < len(names):
        raise BenchError(f"the COLMAP model in {folder} names one image twice")
    return sorted(out, key=lambda nc: nc[0])


def points_seen(folder: Path) -> dict[str, np.ndarray]:
    """The ids of the model's 3D points each image observes, by image name (empty arrays
    for a model without points)."""
    rec = read_reconstruction(folder)
    return {
        image.name: np.array(
            [p.point3D_id for p in image.points2D if p.has_point3D()], dtype=np.int64
        )
        for image in rec.images.values()
    }


def check_images(names: list[str], images: list[str], model: Path, folder: Path) -> None:
    """The model's images are the folder's images: none missing, none left over."""
    missing = sorted(set(names) - set(images))
    if missing:
        raise BenchError(
            f"{len(missing)} image(s) of the model in {model} are not in {folder} "
            f"(first: {missing[0]})"
        )
    extra = sorted(set(images) - set(names))
    if extra:
        raise BenchError(
            f"{folder} holds {len(extra)} image(s) the model in {model} does not pose "
            f"(first: {extra[0]}); move them out, or register them (colmap image_registrator)"
        )
