"""Content-addressed cache entries: a directory written atomically, checked before use.

An entry is complete when its `meta.json` (written last) parses and every file it lists
exists with the recorded size. Writers take a per-entry lock, build the entry in a
temporary directory beside it and rename it into place, so an interrupted write leaves
no entry and two processes filling the same entry do not corrupt it.
"""

from __future__ import annotations

import fcntl
import hashlib
import inspect
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bench import BenchError


def content_key(obj, n: int = 12) -> str:
    """Short stable hash of a JSON-serialisable description."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def source_hash(*code) -> str:
    """Hash of the source of the given modules and functions (the code that decides an
    entry's content, so that changing it invalidates the entry)."""
    h = hashlib.sha256()
    for obj in code:
        h.update(inspect.getsource(obj).encode())
    return h.hexdigest()[:12]


def write_text_atomic(path: Path, text: str) -> None:
    """Write through a temporary name beside `path`, then rename: readers see the old file
    or the new one, never half of one."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def entry_problem(entry: Path) -> str | None:
    """Why `entry` is not a complete cache entry, or None if it is."""
    try:
        meta = json.loads((entry / "meta.json").read_text())
        files = meta["files"]
    except FileNotFoundError:
        return "meta.json missing"
    except (OSError, ValueError, KeyError, TypeError) as e:
        return f"meta.json unreadable ({type(e).__name__})"
    for name, size in files.items():
        p = entry / name
        if not p.is_file():
            return f"{name} missing"
        if p.stat().st_size != size:
            return f"{name} truncated or altered ({p.stat().st_size} bytes, expected {size})"
    return None


def write_meta(directory: Path, meta: dict) -> None:
    """Write `meta.json` last, listing the size of every other file in the directory."""
    files = {p.name: p.stat().st_size for p in sorted(directory.iterdir()) if p.name != "meta.json"}
    (directory / "meta.json").write_text(json.dumps({**meta, "files": files}, indent=1))


@contextmanager
def locked(entry: Path) -> Iterator[None]:
    """Hold an exclusive lock for `entry` (other processes wait)."""
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(entry.parent / f".{entry.name}.lock", os.O_CREAT | os.O_RDWR, 0o644)
    except OSError as e:
        raise BenchError(f"cannot write to {entry.parent}: {e.strerror}") from e
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


@contextmanager
def atomic_dir(entry: Path) -> Iterator[Path]:
    """Yield a temporary directory that replaces `entry` only if the block completes."""
    for stale in entry.parent.glob(f".tmp-{entry.name}-*"):
        shutil.rmtree(stale, ignore_errors=True)  # left by an interrupted writer (we hold the lock)
    tmp = Path(tempfile.mkdtemp(prefix=f".tmp-{entry.name}-", dir=entry.parent))
    try:
        yield tmp
        if entry.exists():
            trash = entry.parent / f".tmp-{entry.name}-old{os.getpid()}"
            entry.rename(trash)
            shutil.rmtree(trash)
        tmp.rename(entry)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
