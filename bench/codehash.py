"""Hashes of the code a cached result depends on: the modules it imports, by content.

`code_hash(modules)` hashes the import closure of `modules` inside the `bench` package
(`closure`): every module of the package that one of them imports, at the top or inside a
function, read from its syntax (not by running it), and the packages above each, over and
over. Each module enters whole, in normal form (`normal_form`: its syntax tree without
docstrings, comments or layout): its decorators and their arguments, its annotations, the
definitions under a top-level `if` or `try`, a `partial`'s bound arguments, the functions
nothing calls yet. So every edit that can change a value the closure computes changes the
hash, and so do some that cannot (a rename, a move, an unused function): the hash errs
toward computing again, never toward reusing a row. Docstrings, comments and layout are
free. (The function-level hash this replaced, 544 lines, covered less and was wrong in
ways its tests did not see: docs/results.md, "Cache keys".)

The sources are those of the files this process runs: `check_unchanged` refuses to record
rows once a module of the package was edited after the process started (`STARTED`), so a
row never carries the hash of code other than the code that computed it. The libraries
whose versions decide a row are named by `library_versions`.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.util
import json
import subprocess
import textwrap
import time
from collections.abc import Callable
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from bench import BenchError

PACKAGE = "bench"
STARTED = time.time()
"""When this process imported the package: a module edited after it is not the code that runs."""
LIBRARIES = ("numpy", "scipy", "opencv-contrib-python-headless", "pycolmap")
"""The libraries whose versions decide every predicted row (features, geometry, COLMAP)."""
MODEL_LIBRARIES = ("scikit-learn",)
"""The libraries a fitted selection model runs (`matchable`; `library_versions(models=True)`)."""


def _strip(body: list[ast.stmt]) -> list[ast.stmt]:
    kept = [
        s
        for s in body
        if not (
            isinstance(s, ast.Expr)
            and isinstance(s.value, ast.Constant)
            and isinstance(s.value.value, str)
        )
    ]
    return kept or [ast.Pass()]


def normal_form(source: str) -> str:
    """The syntax of `source` without docstrings, string statements, comments or layout."""
    tree = ast.parse(textwrap.dedent(source))
    for node in ast.walk(tree):
        for name in ("body", "orelse", "finalbody"):
            body = getattr(node, name, None)
            if isinstance(body, list) and body and isinstance(body[0], ast.stmt):
                setattr(node, name, _strip(body))
    return ast.dump(tree, include_attributes=False)


def _file(module: str, package: str) -> Path | None:
    """The source file of a module of `package` (None for anything else)."""
    if module != package and not module.startswith(package + "."):
        return None
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    origin = getattr(spec, "origin", None)
    return Path(origin) if origin and origin.endswith(".py") else None


Source = Callable[[Path], str]
"""Where a module's text is read from: the file as it is now (`Path.read_text`), or as a
commit held it (`git_source`)."""


def git_source(commit: str) -> Source:
    """The text of a file of this repository as `commit` held it."""
    root = Path(__file__).resolve().parent.parent

    def read(path: Path) -> str:
        rel = path.resolve().relative_to(root).as_posix()
        done = subprocess.run(
            ["git", "show", f"{commit}:{rel}"], cwd=root, capture_output=True, text=True
        )
        if done.returncode:
            raise BenchError(f"cannot read {rel} at commit {commit}: {done.stderr.strip()}")
        return done.stdout

    return read


def _imported(module: str, path: Path, root: str, source: Source = Path.read_text) -> set[str]:
    """The modules of package `root` that `module`'s source imports anywhere in it."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    named = set()
    for node in ast.walk(ast.parse(source(path))):
        if isinstance(node, ast.Import):
            named |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            named |= {base} | {f"{base}.{a.name}" for a in node.names}
    return {m for m in named if _file(m, root) is not None}


def closure(
    modules: tuple[str, ...], package: str = PACKAGE, source: Source = Path.read_text
) -> dict[str, Path]:
    """Every module of `package` that `modules` import, directly or not, with the
    packages above each (whose `__init__` runs first): name -> source file (its text read
    by `source`)."""
    out: dict[str, Path] = {}
    todo = list(modules)
    while todo:
        m = todo.pop()
        if m in out:
            continue
        path = _file(m, package)
        if path is None:
            raise BenchError(f"cannot hash {m}: not a module of {package} with a source")
        out[m] = path
        parts = m.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]
        todo += sorted(_imported(m, path, package, source))
    return dict(sorted(out.items()))


HASHED: set[Path] = set()
"""The files this process has hashed (`check_unchanged` guards them)."""


@cache
def code_hash(modules: tuple[str, ...], package: str = PACKAGE) -> str:
    """Hash of the closure of `modules`, each module in normal form by its name (taken once
    per process: `check_unchanged` guards the files it read)."""
    files = closure(modules, package)
    HASHED.update(files.values())
    return _hash({m: normal_form(p.read_text()) for m, p in files.items()})


def _hash(parts: dict[str, str]) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:12]


def code_record(modules: tuple[str, ...], source: Source = Path.read_text) -> dict:
    """What `code_hash(modules)` hashes, kept to be compared later: the hash (`code`) and
    each module's own (`modules`: module -> the hash of its normal form), read by `source`
    (a commit's: `git_source`)."""
    files = closure(modules, PACKAGE, source)
    parts = {m: normal_form(source(p)) for m, p in files.items()}
    return {"code": _hash(parts), "modules": {m: _hash({m: t}) for m, t in parts.items()}}


def check_unchanged() -> None:
    """Refuse, in one line, when a module this process hashed (`HASHED`) was edited after
    it started: the code that runs is not the code its hashes name. (Modules no hash
    covers, the report's and the command line's, may be edited meanwhile.)"""
    edited = sorted(p for p in HASHED if p.stat().st_mtime > STARTED)
    if edited:
        raise BenchError(
            f"{edited[0]} was edited while this command ran, so the rows it computes from "
            "now on would carry the hash of other code; nothing more is recorded: run the "
            "command again (the rows already written are kept)"
        )


def library_versions(models: bool = False) -> dict[str, str]:
    """The versions of the libraries that decide a predicted row (`LIBRARIES`; with
    `models`, those of fitted selection models; a pool's own: `Pool.identity`)."""
    return versions(LIBRARIES + (MODEL_LIBRARIES if models else ()))


def versions(names) -> dict[str, str]:
    """The installed versions of distributions, by name (`_version`)."""
    return {name: _version(name) for name in names}


@cache
def _version(name: str) -> str:
    """An installed distribution's version ("absent" where it is not installed); read once
    per process (it read each package's metadata every unit: 4 % of a worker's time)."""
    try:
        return version(name)
    except PackageNotFoundError:
        return "absent"
