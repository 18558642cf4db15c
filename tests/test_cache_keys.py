"""Cache keys that name everything that decides a row: the import closure of the code a
row's stages run (`bench.codehash`: every module whole, so no edit that changes a value is
missed; docstrings, comments and layout are free), the settings, the declared fields, the
libraries' versions; a method's own settings decide its rows alone."""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import sys
import textwrap
import time

import pytest

from bench import BenchError, codehash
from bench.codehash import check_unchanged, closure, code_hash

MODULES = {
    "__init__": "",
    "registry": """
POLICIES = {}


def policy(name, memo=1):
    def register(fn):
        POLICIES[name] = (fn, memo)
        return fn

    return register
""",
    "backend": '''
"""The synthetic back end."""

from functools import partial

try:
    import fast_matcher as matcher  # noqa: F401
except ImportError:
    SCALE = 2  # the scale

if SCALE > 1:

    def helper(x):
        """Doubles."""
        return SCALE * x


def match(x, offset=1):
    return helper(x) + offset


MATCH = partial(match, offset=1)
''',
    "settings": """
from dataclasses import dataclass


@dataclass(frozen=True)
class Settings:
    shift: int = 1
""",
    "policies": '''
"""Two synthetic policies."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ckpkg.registry import policy

if TYPE_CHECKING:
    from ckpkg.settings import Settings


@policy("a", memo=1)
def policy_a(x: int, cfg: Settings) -> int:
    return x * 2 + cfg.shift


policy("b", memo=3)(abs)
''',
    "glue": '''
from ckpkg import backend, policies  # noqa: F401 (importing it registers the policies)
from ckpkg.registry import POLICIES


def selection(name, x, budget):
    return POLICIES[name][0](x, budget)


def run(name, x, budget):
    """Runs."""
    return backend.MATCH(selection(name, x, budget)) + late(x)


def late(x):
    from ckpkg.cycle_a import ping

    return ping(x)
''',
    "cycle_a": """
def ping(x):
    from ckpkg.cycle_b import pong

    return pong(x) if x > 0 else 0
""",
    "cycle_b": """
def pong(x):
    from ckpkg.cycle_a import ping

    return ping(x - 2)
""",
    "report": """
from ckpkg import glue


def table(rows):
    return [glue.run("a", r, 4) for r in rows]
""",
}
"""A toy package: `glue.run` is a row's root (`report` only reads rows)."""


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """The toy package in tmp_path; `edit(module, old, new)` rewrites a file and returns
    the root's hash as a new process would take it."""
    root = tmp_path / "ckpkg"
    root.mkdir()
    for name, text in MODULES.items():
        (root / f"{name}.py").write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(codehash, "HASHED", set())  # the toy's files are no run's code
    importlib.invalidate_caches()

    def edit(module: str, old: str, new: str) -> str:
        path = root / f"{module}.py"
        assert old in path.read_text()
        path.write_text(path.read_text().replace(old, new))
        return rows()

    def rows() -> str:
        code_hash.cache_clear()
        return code_hash(("ckpkg.glue",), package="ckpkg")

    yield root, edit, rows
    code_hash.cache_clear()
    for name in [m for m in sys.modules if m.split(".")[0] == "ckpkg"]:
        sys.modules.pop(name)


@pytest.mark.parametrize(
    "module, old, new",
    [
        ("glue", "POLICIES[name][0](x, budget)", "POLICIES[name][0](x, budget // 2)"),  # glue
        ("policies", '@policy("a", memo=1)', '@policy("a", memo=2)'),  # a decorator's argument
        ("backend", "    SCALE = 2", "    SCALE = 3"),  # under a top-level try
        ("backend", "        return SCALE * x", "        return SCALE * x + 1"),  # under an if
        ("settings", "shift: int = 1", "shift: int = 2"),  # reached by an annotation alone
        ("backend", "partial(match, offset=1)", "partial(match, offset=2)"),  # partial's binding
        ("cycle_b", "ping(x - 2)", "ping(x - 1)"),  # a member of an import cycle
        ("cycle_a", "if x > 0 else 0", "if x > 1 else 0"),  # its partner
        ("backend", "def match(x, offset=1):", "def match(x, offset=1, unused=0):"),
        ("policies", 'policy("b", memo=3)(abs)', 'policy("b", memo=4)(abs)'),  # a call statement
    ],
)
def test_every_edit_that_can_change_a_value_changes_the_hash(pkg, module, old, new):
    """The blind spots of the function-level hash this replaced (0.4.0): the harness glue
    between stages, a decorator's arguments, definitions under a top-level `if` or `try`,
    a class reached through an annotation, a `partial`'s bound arguments, a cycle."""
    _, edit, rows = pkg
    before = rows()
    assert edit(module, old, new) != before


@pytest.mark.parametrize(
    "module, old, new",
    [
        ("backend", '"""Doubles."""', '"""Twice its argument, a corrected docstring."""'),
        ("backend", "# the scale", "# the scale factor, a longer comment"),
        ("glue", "def run(name, x, budget):", "\n\ndef run(name, x, budget):  # blank lines"),
        ("glue", '"""Runs."""', '"""Runs the stage."""\n    "a string statement"'),
        ("report", "r, 4)", "r, 8)"),  # a module no root imports
    ],
)
def test_docstrings_comments_layout_and_modules_outside_the_closure_change_no_hash(
    pkg, module, old, new
):
    _, edit, rows = pkg
    before = rows()
    assert edit(module, old, new) == before


def test_the_closure_follows_imports_anywhere_and_stops_at_readers(pkg):
    _, edit, rows = pkg
    found = set(closure(("ckpkg.glue",), package="ckpkg"))
    assert found == {"ckpkg", *(f"ckpkg.{m}" for m in MODULES if m not in ("__init__", "report"))}
    with pytest.raises(BenchError, match="not a module of ckpkg"):
        closure(("ckpkg.missing",), package="ckpkg")


def test_a_module_edited_while_a_command_runs_stops_its_rows(pkg, monkeypatch):
    """The hash is the code that runs: once a module changed after the process started,
    no row is recorded (`bench.codehash.check_unchanged`)."""
    root, edit, rows = pkg
    later = time.time() + 60  # the files were written before this process "started"
    monkeypatch.setattr(codehash, "STARTED", later)
    rows()
    check_unchanged()
    os.utime(root / "report.py", (later + 1, later + 1))  # a module no hash covers
    check_unchanged()
    os.utime(root / "backend.py", (later + 1, later + 1))
    with pytest.raises(BenchError, match=r"backend.py was edited while this command ran"):
        check_unchanged()


def test_the_prediction_code_holds_the_glue_the_peers_and_the_bags():
    """The roots are what a unit stores: every kind's store and the harness around them
    (the policies' selection glue, the peers' extraction options, bags, memos); the report
    and the command line are outside."""
    from bench.harness.keys import PREDICTION_CODE, SCORING_CODE

    modules = set(closure(PREDICTION_CODE))
    assert {
        "bench.unit.predict",
        "bench.unit.bags",
        "bench.harness.execute",
        "bench.backend.peers",
        "bench.frontend.stage",
        "bench.frontend.tracks",
        "bench.memo",
        "bench.evaluation.oracle",
    } <= modules
    assert not any(m.startswith(("bench.report", "bench.cli")) for m in modules)
    assert "bench.evaluation.metrics" in set(closure(SCORING_CODE))
    assert "bench.backend.extraction" in modules


def test_colmaps_extraction_is_keyed_by_its_own_code_alone():
    """How the back end matches, verifies or maps never extracts an image again: the
    extraction's key holds the database's first rows and nothing else of the back end."""
    from bench.backend.extraction import EXTRACTION_CODE

    modules = set(closure(EXTRACTION_CODE))
    assert {"bench.backend.extraction", "bench.backend.database"} <= modules
    assert not modules & {"bench.backend.reconstruction", "bench.backend.matching"}
    assert not modules & {"bench.backend.peers", "bench.vocabulary", "bench.frontend"}


def test_library_versions_decide_the_rows_they_run(monkeypatch):
    """pycolmap, OpenCV, numpy and scipy decide every row; torch a learned method's alone."""
    from bench.harness import keys
    from bench.unit.config import RunConfig

    cfg, methods = RunConfig(), ("scale", "colmap-b", "aliked-b")
    before = {m: keys.prediction_hash(cfg, m, "sfm") for m in methods}
    protocol = {m: keys.protocol_hash(cfg, m, "sfm") for m in methods}
    scored = keys.evaluation_hash()
    real = codehash.version

    def other(lib):
        return lambda name: "9.9" if name == lib else real(name)

    monkeypatch.setattr(codehash, "version", other("pycolmap"))
    codehash._version.cache_clear()  # read once per process: here, the other version
    assert all(keys.prediction_hash(cfg, m, "sfm") != before[m] for m in methods)
    assert all(keys.protocol_hash(cfg, m, "sfm") != protocol[m] for m in methods)
    assert keys.evaluation_hash() != scored
    monkeypatch.setattr(codehash, "version", other("torch"))
    codehash._version.cache_clear()
    changed = {m for m in methods if keys.prediction_hash(cfg, m, "sfm") != before[m]}
    assert changed == {"aliked-b"}
    monkeypatch.setattr(codehash, "version", other("scikit-learn"))  # a fitted model's
    codehash._version.cache_clear()
    assert all(keys.prediction_hash(cfg, m, "sfm") != before[m] for m in methods)
    monkeypatch.undo()
    codehash._version.cache_clear()


def test_the_protocol_is_the_key_but_its_code(monkeypatch):
    """Two parts: the code moves a row's prediction and evaluation hashes, never its
    protocol hash; a setting moves both; a published snapshot's code given back gives back
    its hashes."""
    from bench.harness import keys
    from bench.unit.config import RunConfig

    cfg = RunConfig()
    hashes = lambda c: (  # noqa: E731
        keys.prediction_hash(c, "texture", "sfm"),
        keys.evaluation_hash(),
        keys.protocol_hash(c, "texture", "sfm"),
    )
    before = hashes(cfg)
    code = keys.code_hash(keys.PREDICTION_CODE), keys.code_hash(keys.SCORING_CODE)
    monkeypatch.setattr(keys, "code_hash", lambda modules: "0ther0c0de000")
    edited = hashes(cfg)
    assert edited[0] != before[0] and edited[1] != before[1] and edited[2] == before[2]
    assert keys.prediction_hash(cfg, "texture", "sfm", code[0]) == before[0]
    assert keys.evaluation_hash(code[1]) == before[1]
    other = dataclasses.replace(cfg, backend=dataclasses.replace(cfg.backend, ratio=0.7))
    assert hashes(other)[2] != before[2]


def test_what_a_method_reads_decides_its_rows(monkeypatch):
    """Every declared field but the display ones enters the key: what a method's selection
    reads (`Method.reads`), its pool and matcher; its label does not."""
    from bench.harness import keys
    from bench.unit.config import RunConfig
    from bench.vocabulary import METHODS

    cfg = RunConfig()
    before = keys.prediction_hash(cfg, "texture", "sfm")
    declared = METHODS["texture"]
    monkeypatch.setitem(METHODS, "texture", dataclasses.replace(declared, label="Texture!"))
    assert keys.prediction_hash(cfg, "texture", "sfm") == before
    monkeypatch.setitem(METHODS, "texture", dataclasses.replace(declared, reads=("response",)))
    assert keys.prediction_hash(cfg, "texture", "sfm") != before


def test_a_new_policy_or_a_methods_own_setting_changes_that_methods_rows_alone(tmp_path):
    from bench.frontend import plugins
    from bench.frontend.policies import POLICIES
    from bench.harness import keys
    from bench.unit.config import RunConfig
    from bench.vocabulary import METHODS

    cfg = RunConfig()
    names = [(m, t) for m in METHODS for t in ("tri", "sfm")]
    before = {n: keys.prediction_hash(cfg, *n) for n in names}
    module = tmp_path / "new_policy.py"
    module.write_text(
        textwrap.dedent(
            """
            from bench.frontend.policies import policy

            @policy("cache-keys-new", role="baseline")
            def new_policy(inp, budget, rng, cfg):
                return list(range(min(budget, len(inp.candidates))))
            """
        )
    )
    plugins.load_module(str(module))
    try:
        assert {n: keys.prediction_hash(cfg, *n) for n in names} == before
    finally:  # the registry as it was, for the other tests
        for registry in (METHODS, POLICIES, plugins.ORIGIN):
            registry.pop("cache-keys-new", None)
        plugins.load_module.cache_clear()
    looped = cfg.with_own("adaptive-loop", loop_rounds=3)
    changed = {m for m, t in names if keys.prediction_hash(looped, m, t) != before[(m, t)]}
    assert changed == {"adaptive-loop"}
    weights = tmp_path / "w.json"
    weights.write_text("{}")
    other = cfg.with_own("learned", learned_weights=str(weights))
    changed = {m for m, t in names if keys.prediction_hash(other, m, t) != before[(m, t)]}
    assert changed == {"learned"}


def test_each_task_and_stage_hashes_what_it_reads():
    """A task's rows depend on its own reconstruction and on the settings it reads: an nbv
    setting or a display field changes no tri row; the tasks' keys differ."""
    from bench.harness import keys
    from bench.unit.config import NbvConfig, RunConfig
    from bench.vocabulary import METHODS, deciding

    cfg = RunConfig()
    tri = {m: keys.prediction_hash(cfg, m, "tri") for m in METHODS}
    nbv = dataclasses.replace(cfg, nbv=NbvConfig(initial=4))
    assert {m: keys.prediction_hash(nbv, m, "tri") for m in METHODS} == tri
    assert tri["texture"] != keys.prediction_hash(cfg, "texture", "sfm")
    assert "label" not in deciding(METHODS["texture"])
    assert "matcher" in deciding(METHODS["texture"])


def test_a_methods_own_setting_does_not_bind_the_folder(tmp_path):
    from bench.binding import bind_results_dir, check_results_dir
    from bench.unit.config import RunConfig
    from bench.vocabulary import Vocabulary

    bind_results_dir(tmp_path, RunConfig().as_dict(), Vocabulary.current(), False)
    looped = RunConfig().with_own("adaptive-loop", loop_rounds=3)
    check_results_dir(tmp_path, looped.as_dict(), False)  # no --overwrite needed
    bind_results_dir(tmp_path, looped.as_dict(), Vocabulary.current(), False)
    stored = json.loads((tmp_path / "config.json").read_text())["settings"]
    assert stored["methods"]["adaptive-loop"] == {"loop_rounds": 3}
    assert "loop_rounds" not in stored["policy"]
    ratio = dataclasses.replace(RunConfig(), backend=dataclasses.replace(RunConfig().backend))
    ratio = dataclasses.replace(ratio, backend=dataclasses.replace(ratio.backend, ratio=0.7))
    with pytest.raises(BenchError, match="backend.ratio"):
        check_results_dir(tmp_path, ratio.as_dict(), False)
    old = RunConfig().shared()  # a folder of the code before, loop_rounds a shared setting
    old["policy"] |= {"loop_rounds": 3, "epipolar_weight": 0.28, "learned_weights": ""}
    (tmp_path / "config.json").write_text(json.dumps({"settings": old}))
    check_results_dir(tmp_path, RunConfig().as_dict(), False)


def test_a_setting_added_since_the_folder_was_made_binds_it_only_off_its_default(tmp_path):
    """A folder of the code before backend.matcher existed: extending it at the default
    (the behaviour before) needs no --overwrite; asking for LightGlue does."""
    from bench.binding import check_results_dir
    from bench.unit.config import RunConfig

    old = RunConfig().shared()
    del old["backend"]["matcher"]
    (tmp_path / "config.json").write_text(json.dumps({"settings": old}))
    defaults = RunConfig().as_dict()
    check_results_dir(tmp_path, RunConfig().as_dict(), False, defaults)
    glue = RunConfig()
    glue = dataclasses.replace(glue, backend=dataclasses.replace(glue.backend, matcher="lightglue"))
    with pytest.raises(BenchError, match="backend.matcher"):
        check_results_dir(tmp_path, glue.as_dict(), False, defaults)


def test_a_methods_own_setting_is_set_with_its_name():
    from bench.cli.common import apply_settings
    from bench.unit.config import RunConfig

    run = apply_settings(
        RunConfig(), ["adaptive-loop.loop_rounds=3", "cross-view.epipolar_weight=0.5"]
    )
    assert run.own("adaptive-loop") == {"loop_rounds": 3}
    assert run.policy_config("cross-view").epipolar_weight == 0.5
    assert run.policy_config("adaptive-loop").tiles == run.policy.tiles
    with pytest.raises(BenchError, match=r"--set adaptive-loop.loop_rounds=3"):
        apply_settings(RunConfig(), ["policy.loop_rounds=3"])
    with pytest.raises(BenchError, match="adaptive-loop has no setting 'tiles'"):
        apply_settings(RunConfig(), ["adaptive-loop.tiles=4,4"])
    with pytest.raises(BenchError, match="loop_rounds must be >= 0"):
        apply_settings(RunConfig(), ["adaptive-loop.loop_rounds=-1"]).validate()


def test_the_render_key_covers_the_scenes_and_the_renderer_not_the_rows():
    from bench.render.entry import RENDER_CODE

    modules = set(closure(RENDER_CODE))
    assert {"bench.scenes.generators", "bench.render.mitsuba", "bench.render.develop"} <= modules
    assert {"bench.camera", "bench.scenes.textures"} <= modules
    assert not any(m.startswith(("bench.frontend", "bench.harness")) for m in modules)
