"""Hashes of exactly the code a cached result depends on: its content, not its place.

`code_hash(roots)` covers the top-level definitions (functions, classes, constants)
reachable from `roots` by name: a name of the same module, a name imported from a module
of the `bench` package (at the top or inside a function), or `module.name` through an
imported module; a module passed around as a value counts whole (its definitions by
name). A root is a function, a class or a module; a lambda or a nested function is found
by its code (a task's `reconstruct` registered as a lambda is a root of its own).

The hash is a Merkle tree. A definition's hash is its syntax tree (`ast.dump`, no
positions) with its own name erased and every reference to another definition of the
package replaced by that definition's hash (definitions that reach one another are hashed
as one group), so a rename or a move changes no hash. Left out of the tree:
* every string-only statement (the docstring of a module, class, function or field);
* annotations (type hints decide no value);
* decorators of the package (`@policy(...)`, `@generator(...)`: registrations, whose
  fields that decide a row a key states as data, `bench.vocabulary.Method.deciding`;
  `@last_call(...)`, a memo that decides no value, `bench.memo`);
* a module's statements that bind no name (registrations such as `register(...)`): they
  enter no hash of the module's other definitions; what they register that decides a row
  is a root where it is used (a task's functions) or data (its declared fields).
A definition in `cut` is not entered (its place keeps a mark): it belongs to another hash.
So the code a hash covers is derived from the code, never listed by hand, and a definition
no root reaches (COLMAP text I/O beside the camera model, a sibling policy) is outside it.

A hash changed by a change that keeps every value (a refactoring the code cannot tell from
an edit) is accepted under its new value through `ALIASES` (`accepted`), a tracked file
written only once `benchmarks/compare_runs.py` has proven the values identical
(`benchmarks/alias_hashes.py`).
"""

from __future__ import annotations

import ast
import copy
import hashlib
import importlib
import importlib.util
import inspect
import json
import sys
import textwrap
from dataclasses import dataclass, field
from functools import cache, partial
from pathlib import Path
from types import ModuleType

PACKAGE = "bench"
ALIASES = Path(__file__).with_name("hash_aliases.json")
"""[old, new] pairs: a hash `old` whose values are proven identical to `new`'s."""


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


def strip_strings(tree: ast.AST) -> ast.AST:
    """`tree` without string-only statements and annotations (in place)."""
    for node in ast.walk(tree):
        for name in ("body", "orelse", "finalbody"):
            body = getattr(node, name, None)
            if isinstance(body, list) and body and isinstance(body[0], ast.stmt):
                setattr(node, name, _strip(body))
        if isinstance(node, ast.arg):
            node.annotation = None
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            node.returns = None
        elif isinstance(node, ast.AnnAssign):
            node.annotation = ast.Constant(None)
    return tree


def normal_form(source: str) -> str:
    """The syntax of `source` without docstrings, string statements, comments or layout."""
    tree = strip_strings(ast.parse(textwrap.dedent(source)))
    return ast.dump(tree, include_attributes=False)


def object_digest(obj) -> str:
    """`normal_form` of a module's, class's or function's source."""
    return normal_form(inspect.getsource(obj))


@cache
def _alias_pairs(path: Path) -> tuple[tuple[str, str], ...]:
    try:
        return tuple(tuple(p) for p in json.loads(path.read_text()))
    except FileNotFoundError:
        return ()


def accepted(new: str, path: Path | None = None) -> set[str]:
    """`new` and every older hash aliased to it (through any chain of aliases) in `path`
    (default `ALIASES`)."""
    pairs, out, todo = _alias_pairs(Path(path or ALIASES)), {new}, [new]
    while todo:
        h = todo.pop()
        for old, to in pairs:
            if to == h and old not in out:
                out.add(old)
                todo.append(old)
    return out


@dataclass
class _Module:
    """One module as the hash sees it: its top-level statements by the names they bind."""

    name: str
    tree: ast.Module
    source: str
    defs: dict[str, list[ast.stmt]] = field(default_factory=dict)
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
        ast.AnnAssign: lambda s: [s.target] if s.value is not None else [],
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


def _source(modname: str) -> tuple[ModuleType | None, str | None]:
    """The module `modname` and its source (None, None if it is not Python we can read)."""
    module = sys.modules.get(modname)
    if module is None:
        try:
            module = importlib.import_module(modname)
        except ImportError:
            return None, None
    try:
        return module, inspect.getsource(module)
    except (OSError, TypeError):
        return None, None


def _parse(modname: str) -> _Module | None:
    """The module `modname` (None if it is not Python source we can read)."""
    module, source = _source(modname)
    if source is None:
        return None
    key = (modname, source)
    if key in _PARSED:
        return _PARSED[key]
    tree = strip_strings(ast.parse(source))
    m = _Module(modname, tree, source)
    m.package = modname if hasattr(module, "__path__") else modname.rpartition(".")[0]
    for stmt in tree.body:
        if isinstance(stmt, ast.Import | ast.ImportFrom):
            m.aliases |= _imports(stmt, m.package)
        else:
            for n in _bound(stmt):
                m.defs.setdefault(n, []).append(stmt)
    _PARSED[key] = m
    return m


Target = tuple[str, str | None]
"""(module, top-level name), (module, None) for a whole module, or (module, '<line N>')
for the lambdas and functions defined on line N outside any top-level definition."""


def _within(modname: str, packages) -> bool:
    return any(modname == p or modname.startswith(p + ".") for p in packages)


def _chain(node: ast.AST) -> list[str] | None:
    """`a.b.c` -> [a, b, c] for a loaded name and the attributes read from it."""
    out = []
    while isinstance(node, ast.Attribute):
        out.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
        return [node.id, *reversed(out)]
    return None


def _local_imports(stmts, package: str) -> dict[str, tuple[str, str | None]]:
    """The names bound by imports inside `stmts` (a function's own imports)."""
    out = {}
    for s in stmts:
        for node in ast.walk(s):
            if isinstance(node, ast.Import | ast.ImportFrom) and node is not s:
                out |= _imports(node, package)
    return out


def _anonymous(tree: ast.Module, line: int) -> list[ast.stmt]:
    """The lambdas and functions defined on `line` (a root found by its code)."""
    found = [
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Lambda | ast.FunctionDef | ast.AsyncFunctionDef)
        and (n.lineno == line or any(d.lineno == line for d in getattr(n, "decorator_list", [])))
    ]
    return [ast.Expr(n) if isinstance(n, ast.Lambda) else n for n in found]


class _Walk:
    """The definitions reachable from the roots, their references, and their hashes."""

    def __init__(self, cut: set[Target], cut_packages: tuple[str, ...], packages: tuple[str, ...]):
        self.cut, self.cut_packages, self.packages = cut, cut_packages, packages
        self.modules: dict[str, _Module | None] = {}
        self.stmts: dict[Target, list[ast.stmt]] = {}
        self.edges: dict[Target, list[Target]] = {}
        self.hashes: dict[Target, str] = {}
        self.refs: dict[Target, list] = {}
        self.sources: dict[str, str | None] = {}

    def parsed(self, modname: str) -> _Module | None:
        if modname not in self.modules:
            self.modules[modname] = _parse(modname)
        return self.modules[modname]

    def module(self, modname: str) -> _Module | None:
        """A module the walk may enter (of the packages, not cut), parsed."""
        ours = _within(modname, self.packages) and not _within(modname, self.cut_packages)
        return self.parsed(modname) if ours else None

    def resolve(self, modname: str, chain: list[str], local=None) -> tuple[Target, int] | None:
        """The definition a name chain read in `modname` starts with, and how many of the
        chain's names lead to it (None: not a definition of the packages)."""
        m = self.module(modname)
        if m is None:
            return None
        if not chain:
            return (modname, None), 0
        name, rest = chain[0], chain[1:]
        if local and name in local:
            alias = local[name]
        elif name in m.defs:
            return (modname, name), 1
        elif name in m.aliases:
            alias = m.aliases[name]
        else:
            sub = f"{modname}.{name}"  # a submodule reached as an attribute of its package
            found = None
            if _within(sub, self.packages) and _is_module(sub):
                found = self.resolve(sub, rest)
            return (found[0], found[1] + 1) if found else None
        mod, attr = alias
        if attr is None:
            found = self.resolve(mod, rest)
            return (found[0], found[1] + 1) if found else None
        return self.resolve(mod, [attr, *rest])

    def statements(self, target: Target) -> list[ast.stmt]:
        """The statements that define `target`, without the package's decorators."""
        if target in self.stmts:
            return self.stmts[target]
        modname, name = target
        m = self.parsed(modname)
        if m is None or name is None:
            stmts = []
        elif name.startswith("<line "):
            stmts = _anonymous(m.tree, int(name[6:-1]))
        else:
            stmts = m.defs.get(name, [])
        out = []
        for s in stmts:
            if isinstance(s, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                s = copy.copy(s)
                s.decorator_list = [d for d in s.decorator_list if not self.ours(modname, d)]
            out.append(s)
        self.stmts[target] = out
        return out

    def ours(self, modname: str, decorator: ast.expr) -> bool:
        """Whether a decorator is (a call of) a definition of the packages: a registration."""
        chain = _chain(decorator.func if isinstance(decorator, ast.Call) else decorator)
        return chain is not None and self.resolve(modname, chain) is not None

    def references(self, modname: str, stmts: list[ast.stmt]):
        """Each node of `stmts` (read in `modname`) that names a definition: (node, that
        definition, how many names of the chain lead to it); an import inside a function
        of the packages' names: (node, None, 0)."""
        m = self.parsed(modname)
        if m is None:
            return []
        local = _local_imports(stmts, m.package)
        out, inner = [], set()
        for s in stmts:
            for node in ast.walk(s):
                if id(node) in inner:
                    continue
                if isinstance(node, ast.Import | ast.ImportFrom):
                    bound = _imports(node, m.package).values()
                    if all(self.resolve(mod, [a] if a else []) for mod, a in bound):
                        out.append((node, None, 0))
                    continue
                chain = _chain(node) if isinstance(node, ast.Attribute | ast.Name) else None
                if chain is None:
                    continue
                sub = node
                while isinstance(sub, ast.Attribute):
                    inner.add(id(sub.value))
                    sub = sub.value
                found = self.resolve(modname, chain, local)
                if found:
                    out.append((node, *found))
        return out

    def discover(self, roots: list[Target]) -> None:
        stack = list(roots)
        while stack:
            t = stack.pop()
            if t in self.edges or t in self.cut:
                continue
            if t[1] is None:  # a whole module: its definitions
                m = self.parsed(t[0])
                self.edges[t] = [(t[0], n) for n in (m.defs if m else ())]
            else:
                self.refs[t] = self.references(t[0], self.statements(t))
                self.edges[t] = [r for _, r, _ in self.refs[t] if r is not None]
            stack += self.edges[t]

    def form(self, target: Target, group: set[Target]) -> str:
        """The target's normal form: its own name erased, each reference replaced by the
        hash of what it names (a mark inside its group or for a cut definition)."""
        modname, name = target
        mark = lambda t: self.mark(t, group, target)  # noqa: E731
        if name is None:
            m = self.parsed(modname)
            return repr([(n, mark((modname, n))) for n in sorted(m.defs if m else [])])
        subst = {}
        for node, t, used in self.refs[target]:
            if t is None:  # an import of the packages' names inside a function
                subst[id(node)] = "Pass()"
                continue
            out = f"Name(id={'#' + mark(t)!r},ctx=Load())"
            for attr in (_chain(node) or [])[used:]:
                out = f"Attribute(value={out},attr={attr!r},ctx=Load())"
            subst[id(node)] = out
        stmts = self.statements(target)
        for s in stmts:
            for node in ast.walk(s):
                if isinstance(node, ast.Name) and node.id == name and id(node) not in subst:
                    subst[id(node)] = "Name(id='',ctx=Store())"  # its own name, assigned
        return _dump(stmts, subst, {id(s) for s in stmts})

    def mark(self, t: Target, group: set[Target], me: Target) -> str:
        if t in self.cut:
            return "cut"
        if t == me:
            return "self"
        if t in group:
            return "group"
        return self.hashes[t]

    def stale(self) -> bool:
        """Whether a module the walk read has changed since (its hashes are then not kept)."""
        return any(
            _source(n)[1] != (m.source if m else None) for n, m in list(self.modules.items())
        )

    def hash_all(self) -> None:
        """Each discovered definition's hash, groups (strongly connected) as one."""
        todo = {t: e for t, e in self.edges.items() if t not in self.hashes}
        for group in _groups(todo):
            members = set(group)
            forms = {t: self.form(t, members) for t in group}
            shared = _digest(sorted(forms.values())) if len(group) > 1 else ""
            for t in group:
                self.hashes[t] = _digest([shared, forms[t]])


def _dump(node, subst: dict[int, str], erase: set[int]) -> str:
    """`ast.dump` without positions, a node whose id `subst` holds written as it says and
    the name of a definition whose id `erase` holds left out."""
    if id(node) in subst:
        return subst[id(node)]
    if isinstance(node, list):
        return "[" + ",".join(_dump(n, subst, erase) for n in node) + "]"
    if not isinstance(node, ast.AST):
        return repr(node)
    parts = []
    for f in node._fields:
        value = getattr(node, f, None)
        if f == "name" and id(node) in erase:
            value = ""
        parts.append(f"{f}={_dump(value, subst, erase)}")
    return f"{type(node).__name__}({','.join(parts)})"


def _digest(parts) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode())
        h.update(b"\0")
    return h.hexdigest()


def _groups(edges: dict[Target, list[Target]]) -> list[list[Target]]:
    """Strongly connected groups, each after every group it reaches (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for start in sorted(edges, key=str):
        if start in index:
            continue
        work = [(start, iter(edges[start]))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in edges:
                    continue  # a cut definition
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(edges[w])))
                    advanced = True
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                group = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    group.append(w)
                    if w == v:
                        break
                out.append(sorted(group, key=str))
    return out


def target_of(obj) -> Target:
    """The definition holding a function or class (a method: its class; a nested function:
    the top-level function around it; a lambda outside any: its line), or a whole module."""
    if isinstance(obj, ModuleType):
        return (obj.__name__, None)
    if isinstance(obj, partial):
        return target_of(obj.func)
    obj = inspect.unwrap(obj)
    top = obj.__qualname__.split(".")[0]
    if top.startswith("<"):
        return (obj.__module__, f"<line {obj.__code__.co_firstlineno}>")
    return (obj.__module__, top)


_WALKS: dict[tuple, _Walk] = {}
"""The walks of this process, by what they cut and enter: a definition's hash depends on
the code alone, so it is computed once while no module read has changed."""


def _walk(roots, cut, packages) -> tuple[_Walk, list[Target]]:
    cut_targets = frozenset(target_of(c) for c in cut if not isinstance(c, str))
    cut_packages = tuple(c for c in cut if isinstance(c, str))
    targets = [target_of(r) for r in roots]
    packages = tuple(sorted({*packages, *(m for m, _ in targets)}))
    key = (cut_targets, cut_packages, packages)
    walk = _WALKS.get(key)
    if walk is None or walk.stale():
        walk = _WALKS[key] = _Walk(set(cut_targets), cut_packages, packages)
    walk.discover(targets)
    return walk, targets


def covered(roots, cut=(), packages: tuple[str, ...] = (PACKAGE,)) -> set[Target]:
    """The definitions reachable from `roots` (functions, classes or modules), not entering
    `cut` (functions, classes, modules or package names)."""
    walk, targets = _walk(roots, cut, packages)
    out, stack = set(), [t for t in targets if t in walk.edges]
    while stack:
        t = stack.pop()
        if t not in out:
            out.add(t)
            stack += [e for e in walk.edges[t] if e in walk.edges]
    return out


def code_hash(roots, cut=(), packages: tuple[str, ...] = (PACKAGE,)) -> str:
    """Hash of the code `covered` by `roots` (module docstring): their Merkle hashes."""
    walk, targets = _walk(roots, cut, packages)
    walk.hash_all()
    return _digest(sorted({walk.hashes[t] for t in targets if t in walk.hashes}))[:12]
