"""The package layout: stages in data-flow order, no import cycles, and the ground-truth
firewall (front end and back end never reach ground truth)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import bench

PACKAGE = Path(bench.__file__).parent
STAGES = (
    "scenes",
    "render",
    "frontend",
    "backend",
    "acquisition",
    "evaluation",
    "unit",
    "harness",
    "report",
    "cli",
)
"""The subpackages in data-flow order; the modules directly in `bench/` are shared (here,
not in the package, whose `__init__` is in every code key: bench/__init__.py)."""
FIREWALLED = ("frontend", "backend", "acquisition")
GROUND_TRUTH = ("bench.scenes", "bench.render", "bench.evaluation")
"""What holds or produces ground truth: scene geometry, the renderer, the evaluation."""


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports_of(source: str) -> set[str]:
    """The bench modules a module's source imports (at any depth, functions included);
    `from package import submodule` imports the package too (it runs its `__init__`)."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert not node.level, "relative imports hide the data flow"
            full = {f"{node.module}.{a.name}" for a in node.names}
            found |= {node.module} | (full & MODULES.keys())
    return {m for m in found if m == "bench" or m.startswith("bench.")}


def stage_of(name: str) -> int:
    """Position in the data flow; -1 for the shared modules directly in `bench/`, and the
    top for `python -m bench`."""
    parts = name.split(".")
    if name == "bench.__main__":
        return len(STAGES)
    return STAGES.index(parts[1]) if len(parts) > 1 and parts[1] in STAGES else -1


GRAPH = {name: imports_of(path.read_text()) for name, path in MODULES.items()}


def test_every_stage_is_a_subpackage_with_a_docstring_saying_what_enters_and_leaves():
    for stage in STAGES:
        doc = ast.get_docstring(ast.parse((PACKAGE / stage / "__init__.py").read_text()))
        assert doc and "In:" in doc and "Out:" in doc, stage


def test_no_import_cycles():
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(GRAPH.get(node, ())):
            if nxt == node or nxt not in GRAPH:
                continue
            assert state.get(nxt) != 1, "import cycle: " + " -> ".join([*path, node, nxt])
            if nxt not in state:
                visit(nxt, [*path, node])
        state[node] = 2

    for name in GRAPH:
        if name not in state:
            visit(name, [])


def test_lower_stages_never_import_higher_ones():
    for name, deps in GRAPH.items():
        for dep in deps:
            assert stage_of(dep) <= stage_of(name), (
                f"{name} (stage {stage_of(name)}) imports {dep} (stage {stage_of(dep)})"
            )


GUARDS = {"bench.frontend.plugins"}
"""Modules that name the ground-truth files in order to refuse them (a policy module's
source is checked for them); their imports are checked all the same."""


def firewall_breaches(source: str, name: str) -> set[str]:
    """Ground-truth modules a front- or back-end module imports, and `gt_` file names."""
    bad = {d for d in imports_of(source) if d.startswith(GROUND_TRUTH)}
    return bad | ({"gt_ files"} if "gt_" in source and name not in GUARDS else set())


FIREWALLED_MODULES = [m for m in MODULES if m.split(".")[1:2] in ([f] for f in FIREWALLED)]


@pytest.mark.parametrize("name", FIREWALLED_MODULES)
def test_front_and_back_end_cannot_reach_ground_truth(name):
    assert not firewall_breaches(MODULES[name].read_text(), name)


@pytest.mark.parametrize(
    "planted",
    [
        "from bench.evaluation.layers import read_layers",
        "from bench.evaluation.oracle import oracle_select",
        "import bench.render.entry",
        "from bench.scenes import spec",
        "np.load(entry / 'gt_00.npz')",
    ],
)
def test_the_firewall_check_catches_a_planted_breach(planted):
    source = MODULES["bench.frontend.policies"].read_text() + "\n" + planted + "\n"
    assert firewall_breaches(source, "bench.frontend.policies")


@pytest.mark.parametrize(
    "planted",
    [
        "from bench.evaluation.next_views import best_candidate",
        "from bench.evaluation.truth import SceneTruth",
        "import bench.scenes.catalog",
        "np.load(entry / 'gt_03.npz')",
    ],
)
def test_a_view_chooser_module_reaching_ground_truth_is_refused(planted):
    """The view choosers' stage is firewalled like the front and back end."""
    assert "bench.acquisition.choosers" in FIREWALLED_MODULES
    source = MODULES["bench.acquisition.choosers"].read_text() + "\n" + planted + "\n"
    assert firewall_breaches(source, "bench.acquisition.choosers")


REPORT_MAY_IMPORT = ("bench.report", "bench.vocabulary", "bench.results", "bench.files")
REPORT_MAY_IMPORT += ("bench.runs", "bench.binding")
REPORT_MAY_IMPORT += ("bench.console", "bench.failures")


@pytest.mark.parametrize(
    "name",
    [m for m in MODULES if m.startswith(("bench.report", "bench.vocabulary", "bench.results"))]
    + ["bench.runs", "bench.binding"],
)
def test_the_report_reads_results_and_never_imports_a_stage_that_computes(name):
    """The report stage (and the vocabulary and results contract it reads) import no stage
    that renders, selects, reconstructs or scores: `bench plot` runs without them."""
    assert {d for d in GRAPH[name] if d != "bench" and not d.startswith(REPORT_MAY_IMPORT)} == set()


def test_the_report_check_catches_a_planted_import():
    source = MODULES["bench.report.tables"].read_text() + "\nfrom bench.harness import grid\n"
    assert "bench.harness.grid" in imports_of(source)


def test_no_function_takes_more_than_seven_parameters():
    too_many = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                if n > 7:
                    too_many.append(f"{name}.{node.name} ({n})")
    assert too_many == []


def test_render_entry_or_dataset_is_told_apart_in_one_place():
    """Whether a folder is a render entry is `Source.kind`'s to say (by its record, META)."""
    tests = re.compile(r"META\)\.is_file\(\)")
    deciders = [name for name, path in MODULES.items() if tests.search(path.read_text())]
    assert deciders == ["bench.frontend.views"]


def _strings(tree: ast.AST) -> list[str]:
    """A module's string constants and f-string parts, docstrings left out."""
    docs = {
        id(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)
    }
    return [
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
    ]


def owned_names() -> dict[str, str]:
    """Every file name of a results folder (`bench.results`) and of a cache entry's record
    (`bench.files`), with the module that owns it."""
    from bench import files, results

    names = [results.RUNS, results.DAMAGED, results.CONFIG, results.VOCABULARY]
    names += [results.MANIFEST, results.PAGE, results.GALLERY, results.LOCK, results.LOOP]
    names += [results.POINT_ERRORS, *results.TABLES, results.TRANSFER, results.TRANSFER_RANKS]
    names += [results.png(f) for f in (*results.FIGURES, results.FIGURE_TRANSFER)]
    return {**dict.fromkeys(names, "bench.results"), files.META: "bench.files"}


def test_every_file_name_has_one_owner():
    """A results folder's files are named in `bench.results` (`Workspace`'s module) alone,
    a cache entry's record in `bench.files` alone (a render entry's is read through
    `bench.render.entry.entry_meta`): another module whose code spells one (a string that
    is the name, not prose that mentions it) fails here."""
    owned = owned_names()
    spelled = [
        f"{name}: {text}"
        for name, path in MODULES.items()
        for text in _strings(ast.parse(path.read_text()))
        if text in owned and owned[text] != name
    ]
    assert spelled == []


def test_the_package_map_of_the_docs_names_every_module():
    """docs/extending.md's map of `bench/` lists every module where it is, and no other."""
    text = (PACKAGE.parent / "docs" / "extending.md").read_text()
    block = text.split("```\nbench/\n", 1)[1].split("```", 1)[0]
    listed, package = set(), ""
    for line in block.splitlines():
        head = line[2:].split(" ", 1)[0]
        if line.startswith("  ") and head.endswith("/"):
            package = head
        elif not line.startswith("    ") or line.startswith("               "):
            package = package if line.startswith("               ") else ""
        listed |= {package + w for w in re.findall(r"\b[\w/]+\.py\b", line)}
    on_disk = {
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if p.name not in ("__init__.py", "__main__.py") or p.parent.name == "cli"
    }
    assert listed == on_disk


UNIT_MAY_NOT_IMPORT = ("bench.codehash", "bench.harness")
"""What the unit (`bench.unit`) never imports: the code hashes and the harness, whose
`keys` module computes a row's keys once and hands them in."""


def unit_breaches(source: str) -> set[str]:
    """The hashing or harness modules a unit module's source imports (at any depth)."""
    return {
        d
        for d in imports_of(source)
        if d in UNIT_MAY_NOT_IMPORT or d.startswith(tuple(f"{m}." for m in UNIT_MAY_NOT_IMPORT))
    }


@pytest.mark.parametrize("name", [m for m in MODULES if m.startswith("bench.unit")])
def test_what_decides_a_row_never_imports_the_hashing_or_the_harness(name):
    assert unit_breaches(MODULES[name].read_text()) == set()


@pytest.mark.parametrize(
    "planted",
    [
        "from bench.codehash import code_hash",
        "import bench.codehash",
        "from bench.harness.keys import prediction_hash",
        "from bench.harness import grid",
        "def later():\n    from bench.harness.execute import execute\n",
    ],
)
def test_the_unit_check_catches_a_planted_import(planted):
    source = MODULES["bench.unit.predict"].read_text() + "\n" + planted + "\n"
    assert unit_breaches(source)


def model_reads(source: str) -> int:
    """The calls of a module's source that read a COLMAP model from a folder: pycolmap's
    `Reconstruction(<path>)` (an empty `Reconstruction()` reads nothing)."""
    return sum(
        1
        for n in ast.walk(ast.parse(source))
        if isinstance(n, ast.Call)
        and (n.args or n.keywords)
        and isinstance(n.func, ast.Attribute)
        and n.func.attr == "Reconstruction"
        and getattr(n.func.value, "id", None) == "pycolmap"
    )


def test_a_colmap_model_is_read_in_one_place():
    """Every model of a photo set or an exported prediction is read by one reader
    (`bench.frontend.colmap_model.read_reconstruction`, which `read_model` goes through)."""
    readers = [name for name, path in MODULES.items() if model_reads(path.read_text())]
    assert readers == ["bench.frontend.colmap_model"]
    planted = MODULES["bench.unit.nbv"].read_text() + "\npycolmap.Reconstruction(str(out))\n"
    assert model_reads(planted)
