"""Hashes of exactly the code a cached result depends on, blind to docstrings and comments.

Code is compared as its syntax tree without docstrings (`ast.dump` without positions), so
a comment, a docstring or a blank line changes no hash.

`code_hash(roots, cut)` covers the top-level definitions (functions, classes, constants)
reachable from `roots` by name: a name of the same module, a name imported from a module
of the `bench` package, or `module.name` through an imported module; a module passed
around as a value counts whole. A module's statements that bind no name (registrations
such as `register(...)`) come with any of its definitions. A definition in `cut` is not
entered: it belongs to another hash (another method, another scene, the scoring). So the
modules a hash covers are derived from the code, never listed by hand, and a definition
no root reaches (COLMAP text I/O beside the camera model, a sibling policy) is outside it.
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import importlib.util
import inspect
import sys
import textwrap
from dataclasses import dataclass, field
from types import ModuleType

PACKAGE = "bench"


def strip_docstrings(tree: ast.AST) -> ast.AST:
    """`tree` without the docstrings of its module, classes and functions (in place)."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (
            isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
            and body
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)
        ):
            node.body = body[1:] or [ast.Pass()]
    return tree


def normal_form(source: str) -> str:
    """The syntax of `source` without docstrings, comments or layout."""
    tree = strip_docstrings(ast.parse(textwrap.dedent(source)))
    return ast.dump(tree, include_attributes=False)


def object_digest(obj) -> str:
    """`normal_form` of a module's, class's or function's source."""
    return normal_form(inspect.getsource(obj))


@dataclass
class _Module:
    """One module as the hash sees it: its top-level statements by the names they bind."""

    name: str
    defs: dict[str, list[ast.stmt]] = field(default_factory=dict)
    effects: list[ast.stmt] = field(default_factory=list)
    aliases: dict[str, tuple[str, str | None]] = field(default_factory=dict)
    """Local name -> (module, attribute) of an import (attribute None: the module itself)."""
    package: str = ""


def _is_module(name: str) -> bool:
    if name in sys.modules:
        return True
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def _imports(stmt: ast.Import | ast.ImportFrom, package: str) -> dict[str, tuple[str, str | None]]:
    """The names an import binds -> (module, attribute) (attribute None: the module)."""
    if isinstance(stmt, ast.Import):
        return {
            a.asname or a.name.partition(".")[0]: (
                a.name if a.asname else a.name.partition(".")[0],
                None,
            )
            for a in stmt.names
        }
    base = stmt.module or ""
    if stmt.level:
        parts = package.split(".")
        base = ".".join(parts[: len(parts) - stmt.level + 1] + ([base] if base else []))
    out = {}
    for a in stmt.names:
        sub = f"{base}.{a.name}"
        out[a.asname or a.name] = (sub, None) if _is_module(sub) else (base, a.name)
    return out


def _bound(stmt: ast.stmt) -> list[str]:
    """The names a top-level statement binds (none for a statement run for its effect)."""
    if isinstance(stmt, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return [stmt.name]
    targets = {
        ast.Assign: lambda s: s.targets,
        ast.AnnAssign: lambda s: [s.target],
        ast.AugAssign: lambda s: [s.target],
    }.get(type(stmt))
    if targets is None:
        return []
    names = []
    for t in targets(stmt):
        items = t.elts if isinstance(t, ast.Tuple | ast.List) else [t]
        if not all(isinstance(n, ast.Name) for n in items):
            return []  # an item or an attribute assigned: an effect
        names += [n.id for n in items]
    return names


_PARSED: dict[tuple[str, str], _Module] = {}


def _parse(modname: str) -> _Module | None:
    """The module `modname` (None if it is not Python source we can read)."""
    module = sys.modules.get(modname)
    if module is None:
        try:
            module = importlib.import_module(modname)
        except ImportError:
            return None
    try:
        source = inspect.getsource(module)
    except (OSError, TypeError):
        return None
    key = (modname, source)
    if key in _PARSED:
        return _PARSED[key]
    tree = strip_docstrings(ast.parse(source))
    m = _Module(modname)
    m.package = modname if hasattr(module, "__path__") else modname.rpartition(".")[0]
    for stmt in tree.body:
        if isinstance(stmt, ast.Import | ast.ImportFrom):
            m.aliases |= _imports(stmt, m.package)
        else:
            names = _bound(stmt)
            for n in names:
                m.defs.setdefault(n, []).append(stmt)
            if not names:
                m.effects.append(stmt)
    _PARSED[key] = m
    return m


def _chains(node: ast.AST) -> list[list[str]]:
    """Every name a node loads, with the attributes read from it (`a.b.c` -> [a, b, c])."""
    out = []
    inner: set[int] = set()
    for n in ast.walk(node):
        if isinstance(n, ast.Attribute) and id(n) not in inner:
            chain, base = [], n
            while isinstance(base, ast.Attribute):
                chain.append(base.attr)
                inner.add(id(base.value))
                base = base.value
            if isinstance(base, ast.Name):
                out.append([base.id, *reversed(chain)])
                inner.add(id(base))
        elif isinstance(n, ast.Name) and id(n) not in inner and isinstance(n.ctx, ast.Load):
            out.append([n.id])
    return out


Target = tuple[str, str | None]
"""(module, top-level name), or (module, None) for a whole module."""


def _within(modname: str, packages) -> bool:
    return any(modname == p or modname.startswith(p + ".") for p in packages)


class _Walk:
    def __init__(self, cut: set[Target], cut_packages: tuple[str, ...], packages: tuple[str, ...]):
        self.cut, self.cut_packages, self.packages = cut, cut_packages, packages
        self.seen: set[Target] = set()
        self.parts: dict[Target, list[str]] = {}
        self.modules: dict[str, _Module | None] = {}

    def parsed(self, modname: str) -> _Module | None:
        if modname not in self.modules:
            self.modules[modname] = _parse(modname)
        return self.modules[modname]

    def module(self, modname: str) -> _Module | None:
        """A module the walk may enter (of the packages, not cut), parsed."""
        ours = _within(modname, self.packages) and not _within(modname, self.cut_packages)
        return self.parsed(modname) if ours else None

    def resolve(self, modname: str, chain: list[str]) -> list[Target]:
        m = self.module(modname)
        if m is None:
            return []
        if not chain:
            return [(modname, None)]
        name, rest = chain[0], chain[1:]
        if name in m.defs:
            return [(modname, name)]
        if name in m.aliases:
            mod, attr = m.aliases[name]
            return self.resolve(mod, rest) if attr is None else self.resolve(mod, [attr, *rest])
        sub = f"{modname}.{name}"  # a submodule reached as an attribute of its package
        if _within(sub, self.packages) and _is_module(sub):
            return self.resolve(sub, rest)
        return []

    def visit(self, target: Target) -> None:
        stack = [target]
        while stack:
            t = stack.pop()
            if t in self.seen or t in self.cut:
                continue
            self.seen.add(t)
            modname, name = t
            m = self.parsed(modname)
            if m is None:
                continue
            if name is None:  # a whole module
                stack += [(modname, n) for n in m.defs]
                continue
            stmts = list(m.defs.get(name, []))
            if (modname, "") not in self.seen:  # the module's effects, once
                self.seen.add((modname, ""))
                stmts += m.effects
                self.parts[(modname, "")] = sorted(ast.dump(s) for s in m.effects)
            self.parts[t] = [ast.dump(s) for s in m.defs.get(name, [])]
            for s in stmts:
                for chain in _chains(s):
                    stack += self.resolve(modname, chain)
                for node in ast.walk(s):  # an import inside a function: what it imports
                    if isinstance(node, ast.Import):
                        for a in node.names:
                            stack += self.resolve(a.name, [])
                    elif isinstance(node, ast.ImportFrom):
                        for mod, attr in _imports(node, m.package).values():
                            stack += self.resolve(mod, [attr] if attr else [])


def target_of(obj) -> Target:
    """The top-level definition holding a function or class (a method: its class), or a
    whole module."""
    if isinstance(obj, ModuleType):
        return (obj.__name__, None)
    obj = inspect.unwrap(obj)
    return (obj.__module__, obj.__qualname__.split(".")[0])


def covered(roots, cut=(), packages: tuple[str, ...] = (PACKAGE,)) -> dict[Target, list[str]]:
    """The definitions reachable from `roots` (functions, classes or modules), not entering
    `cut` (functions, classes, modules or package names), each with its normal form."""
    cut_targets = {target_of(c) for c in cut if not isinstance(c, str)}
    cut_packages = tuple(c for c in cut if isinstance(c, str))
    roots = [target_of(r) for r in roots]
    walk = _Walk(cut_targets, cut_packages, packages + tuple({m for m, _ in roots}))
    for r in roots:
        walk.visit(r)
    return walk.parts


def code_hash(roots, cut=(), packages: tuple[str, ...] = (PACKAGE,)) -> str:
    """Hash of the code `covered` by `roots` (module docstring)."""
    h = hashlib.sha256()
    for (modname, name), parts in sorted(covered(roots, cut, packages).items(), key=str):
        h.update(f"{modname}:{name}\n".encode())
        for p in parts:
            h.update(p.encode())
    return h.hexdigest()[:12]
