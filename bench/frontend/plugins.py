"""Policies and pools from outside the package: a Python file (`bench run --policy-module
FILE`, `--pool-module FILE`) or an installed package's `bench.policies` entry point,
registered with `bench.frontend.policies.policy` (a pool: `bench.frontend.pools.register_pool`)
like the package's own.

The contract's last rule, no ground truth, is checked twice. It guards against accidents
and slips, not against code written to get around it.

* Before a module runs, its syntax tree is checked (`ground_truth_use`): it may not import
  the scene, render, evaluation or harness stages (`import`, `from ... import`, and
  `importlib.import_module` / `__import__` with a literal name), import a module by a
  computed name, read `sys.modules`, or hold a string literal naming a ground-truth file
  (`gt_NN.npz`, `meta.json`, `ground_truth/`). Docstrings and comments are not checked.
* While a module is imported and while any policy selects (`firewall`, in
  `bench.frontend.selection`), in that thread: importing one of those stages raises, by
  any name (`import`, `__import__`, `importlib.import_module`), and so does opening a
  ground-truth file from Python (`open`, `io`, `os.open`, numpy, pathlib) or listing a
  `ground_truth/` folder. A policy itself gets arrays and a file name, never a path.

Not caught: a module reached without an import (an attribute of an imported package,
such as `bench.evaluation` after `import bench`; `gc`; a frame's globals), files read by
native code (OpenCV's `imread`), a policy that catches the error and goes on, and
ground truth copied under another name. The other rules are checked on every selection
(`bench.frontend.policies.select`).
"""

from __future__ import annotations

import ast
import builtins
import importlib
import importlib.util
import os
import re
import sys
import threading
from contextlib import contextmanager
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path

from bench import BenchError
from bench.files import checksum, content_key
from bench.frontend.pools import ORIGIN as POOL_ORIGIN
from bench.frontend.pools import POOLS
from bench.vocabulary import METHODS

FORBIDDEN_IMPORTS = ("bench.scenes", "bench.render", "bench.evaluation", "bench.harness")
FORBIDDEN_TEXT = re.compile(r"gt_\d|gt_\{|meta\.json|ground_truth|groundtruth")
ENTRY_POINT_GROUP = "bench.policies"
ORIGIN: dict[str, str] = {}
"""The source file of every policy registered from outside the package."""


IMPORT_CALLS = ("import_module", "__import__")


def _forbidden(name: str) -> bool:
    return any(name == f or name.startswith(f + ".") for f in FORBIDDEN_IMPORTS)


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the string constants that are statements of their own (docstrings)."""
    return {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    }


def _literal(node: ast.AST) -> str | None:
    """A string expression's value when it is made of literals alone (`"a" + "b"`)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = _literal(node.left), _literal(node.right)
        return None if left is None or right is None else left + right
    return None


def _call_name(node: ast.Call) -> str:
    f = node.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def ground_truth_use(source: str, where: str) -> str | None:
    """Why a policy module's source could read ground truth, or None (module docstring)."""
    try:
        tree = ast.parse(source)
    except SyntaxError as e:
        raise BenchError(f"policy module {where} is not valid Python: {e}") from None
    docs = _docstrings(tree)
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Call) and _call_name(node) in IMPORT_CALLS and node.args:
            name = _literal(node.args[0])
            if name is None:
                return f"it imports a module by a computed name (line {node.lineno})"
            names = [name]
        elif (
            isinstance(node, ast.Attribute)
            and node.attr == "modules"
            and isinstance(node.value, ast.Name)
            and node.value.id == "sys"
        ):
            names = ["sys.modules"]
        if "sys.modules" in names:
            return f"it reads sys.modules (line {node.lineno})"
        for name in names:
            if _forbidden(name):
                return f"it imports {name} (line {node.lineno})"
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if FORBIDDEN_TEXT.search(node.value):
                return f"it names ground truth: {node.value!r} (line {node.lineno})"
    return None


class GroundTruthRead(Exception):
    """Code running under `firewall` imported a forbidden stage or opened ground truth."""


_GUARD = threading.local()
GROUND_TRUTH_PATH = re.compile(r"(^|[/\\])(gt_\d+\.npz|meta\.json|ground_truth)([/\\]|$)")


def _audit(event: str, args: tuple) -> None:
    """Refuse, in a guarded thread, opening or listing ground truth."""
    if not getattr(_GUARD, "depth", 0) or event not in ("open", "os.listdir", "os.scandir"):
        return
    path = args[0] if args else None
    if isinstance(path, str | bytes | os.PathLike) and GROUND_TRUTH_PATH.search(os.fsdecode(path)):
        raise GroundTruthRead(f"broke the contract rule 'no ground truth': it opened {path}")


def _check_import(name: str, fromlist=()) -> None:
    for full in (name, *(f"{name}.{x}" for x in fromlist or ())):
        if getattr(_GUARD, "depth", 0) and _forbidden(full):
            raise GroundTruthRead(f"broke the contract rule 'no ground truth': it imported {full}")


_REAL: dict = {}
"""The import functions the guards wrap."""


def _guarded_import(name, globals=None, locals=None, fromlist=(), level=0):
    if level == 0:
        _check_import(name, fromlist)
    return _REAL["import"](name, globals, locals, fromlist, level)


def _guarded_import_module(name, package=None):
    _check_import(importlib.util.resolve_name(name, package) if name.startswith(".") else name)
    return _REAL["import_module"](name, package)


@cache
def _install_guards() -> None:
    """The audit hook and the import wrappers, once for the life of the process; they act
    in a thread inside `firewall` only."""
    _REAL.update({"import": builtins.__import__, "import_module": importlib.import_module})
    builtins.__import__, importlib.import_module = _guarded_import, _guarded_import_module
    sys.addaudithook(_audit)


@contextmanager
def firewall():
    """Run a block where importing a forbidden stage or opening ground truth raises
    `GroundTruthRead` (in this thread; module docstring)."""
    _install_guards()
    _GUARD.depth = getattr(_GUARD, "depth", 0) + 1
    try:
        yield
    finally:
        _GUARD.depth -= 1


def _check(source: str, where: str) -> None:
    why = ground_truth_use(source, where)
    if why:
        raise BenchError(f"policy module {where} broke the contract rule 'no ground truth': {why}")


@cache
def load_module(path: str) -> tuple[str, ...]:
    """Register the policies of one file; the names it added."""
    file = Path(path)
    if not file.is_file():
        raise BenchError(f"policy module {path} does not exist")
    _check(file.read_text(), path)
    before, pools = set(METHODS), set(POOLS)
    name = f"bench_policy_module_{content_key(str(file.resolve()), 8)}"
    spec = importlib.util.spec_from_file_location(name, file)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        with firewall():
            spec.loader.exec_module(module)
    except BenchError as e:  # a name taken, an unknown signal
        raise BenchError(f"policy module {path}: {e}") from None
    except GroundTruthRead as e:
        raise BenchError(f"policy module {path} {e}") from None
    except (Exception, SystemExit) as e:
        raise BenchError(f"policy module {path} failed to import: {type(e).__name__}: {e}") from e
    added = tuple(p for p in METHODS if p not in before)
    new_pools = [p for p in POOLS if p not in pools]
    if not added and not new_pools:
        raise BenchError(
            f"policy module {path} registers no new policy or pool (decorate a function with "
            "@bench.frontend.policies.policy('name'), or call "
            "bench.frontend.pools.register_pool)"
        )
    ORIGIN.update(dict.fromkeys(added, str(file.resolve())))
    POOL_ORIGIN.update(dict.fromkeys(new_pools, str(file.resolve())))
    return added


@cache
def load_entry_points() -> tuple[str, ...]:
    """Register the policies of installed packages (entry point group `bench.policies`)."""
    before = set(METHODS)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        module = sys.modules.get(ep.module) or importlib.util.find_spec(ep.module)
        origin = getattr(module, "origin", None) or getattr(module, "__file__", None)
        if origin and Path(origin).is_file():
            _check(Path(origin).read_text(), f"{ep.module} (entry point {ep.name})")
        names = set(METHODS)
        try:
            with firewall():
                ep.load()
        except Exception as e:
            raise BenchError(f"policy entry point {ep.name} failed: {type(e).__name__}: {e}") from e
        if origin:
            ORIGIN.update(dict.fromkeys(set(METHODS) - names, str(origin)))
    return tuple(p for p in METHODS if p not in before)


def load(modules=()) -> None:
    """Register every outside policy: installed entry points, then the given files."""
    load_entry_points()
    for m in modules:
        load_module(str(m))


def files_hash(paths) -> str:
    """Hash of the contents of files (a missing one hashes as missing)."""
    return content_key([checksum(p) if Path(p).is_file() else "missing" for p in paths])
