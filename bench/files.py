"""Files the harness writes: content hashes, atomic writes and cache entries.

A cache entry is a directory that is complete when its `meta.json` (written last) parses
and every file it lists exists with the recorded size and CRC-32 checksum (so a file
overwritten with other bytes of the same size is caught too). Writers take a per-entry
lock, build the entry in a temporary directory beside it and rename it into place, so an
interrupted write leaves no entry and two processes filling the same entry do not corrupt
it. Lock files and temporary files never outlive the writer, and everything written gets
the permissions of the user's umask.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import tempfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import numpy as np

from bench import BenchError

META = "meta.json"
"""A cache entry's record, written last (`write_meta`): its own fields and each file's size
and checksum."""


def content_key(obj, n: int = 12) -> str:
    """Short stable hash of a JSON-serialisable description."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def temp_dir_beside(target: Path) -> Path:
    """A new temporary directory beside `target` (to be renamed onto it), with the
    permissions the user's umask gives a directory (mkdtemp alone makes it 0700)."""
    tmp = Path(tempfile.mkdtemp(prefix=f".tmp-{target.name}-", dir=target.parent))
    tmp.chmod(0o777 & ~_umask())
    return tmp


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary name beside `path` (this process's own, with the same suffix) to write
    to; renamed onto `path` when the block completes, removed if it fails (a clean-up that
    fails too, e.g. on a read-only file system, never hides the error that ended the
    block): readers see the old file or the new one, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        tmp.replace(path)
    except BaseException:
        with suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """Write text through `atomic_path`."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def checksum(path: Path) -> str:
    """CRC-32 of a file's bytes, as 8 hex digits (catches damage, not tampering)."""
    return f"{zlib.crc32(Path(path).read_bytes()):08x}"


_VERIFIED: set[tuple] = set()
"""The entries this process found whole: their meta.json and each file's size, time and inode."""


def entry_problem(entry: Path) -> str | None:
    """Why `entry` is not a complete, undamaged cache entry, or None if it is. The checksums
    are computed once per process: again only when the meta or a file's size, modification
    time or inode changes."""
    try:
        text = (entry / META).read_text()
        files = json.loads(text)["files"]
    except FileNotFoundError:
        return f"{META} missing"
    except (OSError, ValueError, KeyError, TypeError) as e:
        return f"{META} unreadable ({type(e).__name__})"
    stats, crcs = [], {}
    for name, rec in files.items():
        p = entry / name
        if not isinstance(rec, dict) or not {"bytes", "crc32"} <= rec.keys():
            return f"{META} unreadable (no size and checksum for {name})"
        size, crcs[name] = rec["bytes"], rec["crc32"]
        if not p.is_file():
            return f"{name} missing"
        st = p.stat()
        if st.st_size != size:
            return f"{name} truncated or altered ({st.st_size} bytes, expected {size})"
        stats.append((name, st.st_size, st.st_mtime_ns, st.st_ino))
    key = (str(Path(entry).resolve()), text, tuple(stats))
    if key in _VERIFIED:
        return None
    for name, crc in crcs.items():
        if checksum(entry / name) != crc:
            return f"{name} altered (its checksum differs from the one recorded)"
    _VERIFIED.add(key)
    return None


def read_meta(entry: Path) -> dict:
    """A cache entry's record (`META`)."""
    return json.loads((Path(entry) / META).read_text())


def write_meta(directory: Path, meta: dict) -> None:
    """Write `meta.json` last, listing the size and checksum of every other file."""
    files = {
        p.name: {"bytes": p.stat().st_size, "crc32": checksum(p)}
        for p in sorted(directory.iterdir())
        if p.name != META
    }
    write_text_atomic(directory / META, json.dumps({**meta, "files": files}, indent=1))


@contextmanager
def _lock_file(path: Path, wait: bool, what: str) -> Iterator[None]:
    """Hold the lock file `path` for the block: waiting for another holder, or (not `wait`)
    refusing at once, in one line naming `what`. The holder removes the file; a process
    that takes a file its holder has just removed takes a fresh one."""
    while True:
        try:
            fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o666)
        except OSError as e:
            raise BenchError(f"cannot write to {path.parent}: {e.strerror}") from e
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise BenchError(
                f"{what} is in use by another bench process (pid {holder}); wait for it to "
                "finish, or use another folder"
            ) from None
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break  # still the lock file on disk: ours
        except FileNotFoundError:
            pass
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, str(os.getpid()).encode())
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def locked(entry: Path):
    """Hold an exclusive lock for the cache entry `entry` (other processes wait)."""
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(f"cannot write to {entry.parent}: {e.strerror}") from e
    return _lock_file(entry.parent / f".{entry.name}.lock", True, str(entry))


def exclusive(path: Path, what: str):
    """Hold the lock file `path`, or refuse at once while another process holds it."""
    return _lock_file(path, False, what)


@contextmanager
def atomic_dir(entry: Path) -> Iterator[Path]:
    """Yield a temporary directory that replaces `entry` only if the block completes. The
    caller holds `entry`'s lock, so every `.tmp-<entry>-*` beside it is this writer's or an
    interrupted one's: all are removed on the way out, also one a signal left between its
    creation and the block (a signal during `bench render` left one)."""
    temporary = f".tmp-{entry.name}-*"
    try:
        for stale in entry.parent.glob(temporary):
            shutil.rmtree(stale, ignore_errors=True)
        tmp = temp_dir_beside(entry)
        yield tmp
        if entry.exists():
            trash = entry.parent / f".tmp-{entry.name}-old{os.getpid()}"
            entry.rename(trash)
            shutil.rmtree(trash)
        tmp.rename(entry)
    finally:
        for left in entry.parent.glob(temporary):
            shutil.rmtree(left, ignore_errors=True)


def image_pixels_key(image: np.ndarray) -> str:
    """SHA-256 of an image's decoded 8-bit values and shape (not of a file's bytes, which
    depend on the encoder)."""
    digest = hashlib.sha256(str(image.shape).encode())
    digest.update(np.ascontiguousarray(image).tobytes())
    return digest.hexdigest()


def images_pixels_key(keys: list[str]) -> str:
    """The `pixels` of a set of views: their `image_pixels_key`s, in view order."""
    return "px-" + hashlib.sha256("\n".join(keys).encode()).hexdigest()[:12]


def views_pixels(images: list[Path]) -> str:
    """The `pixels` of a set of views from their image files, in view order (a render
    entry's, where its meta does not record them)."""
    import cv2

    return images_pixels_key([image_pixels_key(cv2.imread(str(p))) for p in images])
