"""Policies from outside the package: a Python file (`bench run --policy-module FILE`) or
an installed package's `bench.policies` entry point, registered with
`bench.frontend.policies.policy` like the package's own.

Before it runs, a policy module's source is checked for the contract's last rule, no
ground truth: it may not import the scene, render, evaluation or harness stages, nor name
the ground-truth files (`gt_NN.npz`, `meta.json`, `ground_truth/`). The other rules are
checked on every selection (`bench.frontend.policies.select`).
"""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path

from bench import BenchError
from bench.files import checksum, content_key
from bench.frontend.policies import POLICIES

FORBIDDEN_IMPORTS = ("bench.scenes", "bench.render", "bench.evaluation", "bench.harness")
FORBIDDEN_TEXT = re.compile(r"gt_\d|gt_\{|meta\.json|ground_truth|groundtruth")
ENTRY_POINT_GROUP = "bench.policies"
ORIGIN: dict[str, str] = {}
"""The source file of every policy registered from outside the package."""


def ground_truth_use(source: str, where: str) -> str | None:
    """Why a policy module's source could read ground truth, or None."""
    try:
        tree = ast.parse(source)
    except SyntaxError as e:
        raise BenchError(f"policy module {where} is not valid Python: {e}") from None
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for name in names:
            if name.startswith(FORBIDDEN_IMPORTS):
                return f"it imports {name} (line {node.lineno})"
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if FORBIDDEN_TEXT.search(node.value):
                return f"it names ground truth: {node.value!r} (line {node.lineno})"
    return None


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
    before = set(POLICIES)
    name = f"bench_policy_module_{content_key(str(file.resolve()), 8)}"
    spec = importlib.util.spec_from_file_location(name, file)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BenchError as e:  # a name taken, an unknown signal
        raise BenchError(f"policy module {path}: {e}") from None
    except (Exception, SystemExit) as e:
        raise BenchError(f"policy module {path} failed to import: {type(e).__name__}: {e}") from e
    added = tuple(p for p in POLICIES if p not in before)
    if not added:
        raise BenchError(
            f"policy module {path} registers no new policy (decorate a function with "
            "@bench.frontend.policies.policy('name'))"
        )
    ORIGIN.update(dict.fromkeys(added, str(file.resolve())))
    return added


@cache
def load_entry_points() -> tuple[str, ...]:
    """Register the policies of installed packages (entry point group `bench.policies`)."""
    before = set(POLICIES)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        module = sys.modules.get(ep.module) or importlib.util.find_spec(ep.module)
        origin = getattr(module, "origin", None) or getattr(module, "__file__", None)
        if origin and Path(origin).is_file():
            _check(Path(origin).read_text(), f"{ep.module} (entry point {ep.name})")
        names = set(POLICIES)
        try:
            ep.load()
        except Exception as e:
            raise BenchError(f"policy entry point {ep.name} failed: {type(e).__name__}: {e}") from e
        if origin:
            ORIGIN.update(dict.fromkeys(set(POLICIES) - names, str(origin)))
    return tuple(p for p in POLICIES if p not in before)


def load(modules=()) -> None:
    """Register every outside policy: installed entry points, then the given files."""
    load_entry_points()
    for m in modules:
        load_module(str(m))


def files_hash(paths) -> str:
    """Hash of the contents of files (a missing one hashes as missing)."""
    return content_key([checksum(p) if Path(p).is_file() else "missing" for p in paths])
