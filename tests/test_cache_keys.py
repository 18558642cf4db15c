"""Cache keys as narrow as what they protect, by content: a rename, a move, a docstring
or string, an annotation, a display label or an unused function changes no hash; an edit
in one policy changes that policy's rows alone, an edit in the shared back end every row;
a method's rows depend on its own code and settings, a scene's render key on its own
generator."""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
import textwrap

import pytest

from bench import BenchError
from bench.codehash import accepted, code_hash, covered, object_digest

REGISTRY = """
POLICIES = {}


def policy(name, label):
    def register(fn):
        POLICIES[name] = fn
        return fn

    return register
"""

BACKEND = '''
"""The synthetic back end."""

SCALE = 2  # the scale


def helper(x):
    """Doubles."""
    return SCALE * x


def match(x):
    return helper(x) + 1


def colmap_io(path):
    """Not reached by any row."""
    return open(path).read()


def lazy(x):
    return x * 3
'''

POLICIES = '''
"""Two synthetic policies."""

from dataclasses import dataclass

from ckpkg.registry import policy


@dataclass(frozen=True)
class Settings:
    """A policy's settings."""

    shift: int = 1
    """How far it shifts."""


@policy("a", "Policy A")
def policy_a(x: int) -> int:
    return _order(x) + Settings().shift


@policy("b", "Policy B")
def policy_b(x):
    return _order(x) - 1


def _order(x):
    return x * 2
'''

STAGE = '''
"""The synthetic shared path."""

from ckpkg import backend
from ckpkg.registry import POLICIES


def run(name, x):
    """Runs."""
    return backend.match(POLICIES[name](x)) + late(x)


def late(x):
    from ckpkg.backend import lazy

    return lazy(x)
'''

MODULES = {"registry": REGISTRY, "backend": BACKEND, "policies": POLICIES, "stage": STAGE}


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """The synthetic package written to tmp_path and imported; `edit(module, old, new)`
    rewrites one of its files (the imported modules are hashed from their files), `rows()`
    each policy's row key: the shared path's hash and the policy's own."""
    root = tmp_path / "ckpkg"
    root.mkdir()
    (root / "__init__.py").write_text("")
    for name, text in MODULES.items():
        (root / f"{name}.py").write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    names = ["ckpkg", *(f"ckpkg.{m}" for m in MODULES)]
    for name in names:
        sys.modules.pop(name, None)
    importlib.import_module("ckpkg.policies")
    stage = importlib.import_module("ckpkg.stage")
    importlib.import_module("ckpkg.registry")

    def edit(module: str, old: str, new: str) -> None:
        path = root / f"{module}.py"
        text = path.read_text()
        assert old in text
        path.write_text(text.replace(old, new))

    def rows() -> dict[str, tuple[str, str]]:
        """Each policy's row key, the package imported anew (a process of the code now)."""
        for name in names:
            sys.modules.pop(name, None)
        importlib.import_module("ckpkg.policies")
        stage = importlib.import_module("ckpkg.stage")
        registry = importlib.import_module("ckpkg.registry")
        shared = code_hash([stage.run], packages=("ckpkg",))
        own = {p: code_hash([fn], packages=("ckpkg",)) for p, fn in registry.POLICIES.items()}
        return {p: (shared, h) for p, h in own.items()}

    yield stage, edit, rows
    for name in names:
        sys.modules.pop(name, None)


MOVE_ORDER = [
    ("policies", "\n\ndef _order(x):\n    return x * 2\n", "\n"),
    (
        "policies",
        "from ckpkg.registry import policy",
        "from ckpkg.backend import _order\nfrom ckpkg.registry import policy",
    ),
    ("backend", "\ndef lazy(x):", "\ndef _order(x):\n    return x * 2\n\n\ndef lazy(x):"),
]


@pytest.mark.parametrize(
    "edits",
    [
        [("backend", "helper", "twice")],  # a rename: its definition and its uses
        [("policies", "_order", "_sorted")],
        [("policies", "policy_a", "select_a")],  # a policy's function renamed
        [("backend", "SCALE", "FACTOR")],  # a constant renamed
        MOVE_ORDER,  # a helper moved to another module
        [("backend", '"""Doubles."""', '"""Twice its argument, a corrected docstring."""')],
        [("policies", '"""How far it shifts."""', '"""How far, a field docstring."""')],
        [("stage", "    return lazy(x)", '    "a string statement"\n    return lazy(x)')],
        [("backend", "# the scale", "# the scale factor, a longer comment")],
        [("stage", "def run(name, x):", "\n\ndef run(name, x):  # blank lines")],
        [("policies", "def policy_a(x: int) -> int:", "def policy_a(x: float) -> float:")],
        [("policies", '"Policy A"', '"Policy A, its display label"')],  # registration
        [("backend", "def colmap_io(path):", "def colmap_io(path, mode='r'):")],  # unreached
        [("backend", "\ndef lazy", "\ndef unused(x):\n    return 0\n\n\ndef lazy")],  # new
    ],
)
def test_renames_moves_strings_and_unused_code_change_no_hash(pkg, edits):
    stage, edit, rows = pkg
    before = rows()
    for module, old, new in edits:
        edit(module, old, new)
    assert rows() == before


@pytest.mark.parametrize(
    "module, old, new",
    [
        ("backend", "return SCALE * x", "return SCALE * x + 1"),  # a function the path calls
        ("backend", "SCALE = 2", "SCALE = 3"),  # a constant it reads, through the module
        ("backend", "return x * 3", "return x * 4"),  # imported inside a function
        ("stage", "+ late(x)", "- late(x)"),
    ],
)
def test_an_edit_in_the_back_end_changes_every_rows_key(pkg, module, old, new):
    stage, edit, rows = pkg
    before = rows()
    edit(module, old, new)
    after = rows()
    assert all(after[p] != before[p] for p in before)


@pytest.mark.parametrize(
    "old, new",
    [
        ("return _order(x) + Settings().shift", "return _order(x) + Settings().shift + 1"),
        ("shift: int = 1", "shift: int = 2"),  # its settings class
    ],
)
def test_an_edit_in_one_policy_changes_its_rows_alone(pkg, old, new):
    stage, edit, rows = pkg
    before = rows()
    edit("policies", old, new)
    after = rows()
    assert after["a"] != before["a"] and after["b"] == before["b"]
    edit("policies", "return x * 2", "return x * 3")  # a helper both policies call
    assert all(rows()[p] != after[p] for p in after)


def test_a_cut_function_belongs_to_its_own_hash(pkg):
    """A function cut out of a hash: editing it changes its own hash and not the other."""
    stage, edit, rows = pkg
    from ckpkg import backend

    cut = code_hash([stage.run], cut=[backend.helper], packages=("ckpkg",))
    own = code_hash([backend.helper], packages=("ckpkg",))
    edit("backend", "return SCALE * x", "return SCALE * x + 1")
    assert code_hash([stage.run], cut=[backend.helper], packages=("ckpkg",)) == cut
    assert code_hash([backend.helper], packages=("ckpkg",)) != own


def test_a_lambda_is_a_root_of_its_own(pkg, tmp_path):
    """A function registered as a lambda (a task's `reconstruct`) is hashed by its code,
    not by the statement that registers it."""
    stage, edit, rows = pkg
    edit(
        "registry",
        "POLICIES = {}",
        "POLICIES = {}\nTASKS = {\n    't': lambda x: x + 1,\n    'u': lambda x: x - 1,\n}",
    )
    registry = importlib.reload(sys.modules["ckpkg.registry"])
    before = code_hash([registry.TASKS["t"]], packages=("ckpkg",))
    edit("registry", "lambda x: x - 1", "lambda x: x - 2")
    assert code_hash([registry.TASKS["t"]], packages=("ckpkg",)) == before
    edit("registry", "lambda x: x + 1", "lambda x: x + 2")
    assert code_hash([registry.TASKS["t"]], packages=("ckpkg",)) != before


def test_an_aliased_hash_is_accepted(tmp_path):
    """A hash aliased to the current one (values proven identical) is accepted for it,
    through a chain of aliases, and no other."""
    aliases = tmp_path / "aliases.json"
    aliases.write_text(json.dumps([["old", "mid"], ["mid", "new"], ["other", "elsewhere"]]))
    assert accepted("new", aliases) == {"new", "mid", "old"}
    assert accepted("elsewhere", aliases) == {"elsewhere", "other"}
    assert accepted("unknown", aliases) == {"unknown"}


def test_a_digest_ignores_docstrings_and_comments(pkg):
    stage, edit, rows = pkg
    before = object_digest(stage)
    edit("stage", '"""Runs."""', '"""Runs the stage (a longer docstring)."""  # and a comment')
    assert object_digest(stage) == before
    edit("stage", "+ late(x)", "- late(x)")
    assert object_digest(stage) != before


def test_the_shared_prediction_code_is_the_select_and_match_path_alone():
    from bench.frontend import policies
    from bench.harness import predict

    parts = covered(predict.SHARED_CODE)
    modules = {m for m, _ in parts}
    assert {"bench.frontend.signals", "bench.backend.matching"} <= modules
    assert not any(m.startswith(("bench.evaluation", "bench.report")) for m in modules)
    assert ("bench.codehash", "code_hash") not in parts  # the caching around it
    assert ("bench.harness.predict", "read_record") not in parts
    assert ("bench.frontend.stage", "front_end") not in parts
    assert ("bench.frontend.policies", "adaptive_policy") not in parts
    assert ("bench.frontend.policies", "select") in parts  # the contract every policy meets
    assert ("bench.frontend.feedback", "feedback_select") not in parts
    assert ("bench.frontend.tracks", "track_first_select") not in parts  # registered
    own = covered([policies.POLICIES["adaptive"]])
    assert ("bench.frontend.policies", "capped_greedy") in own
    assert ("bench.frontend.policies", "random_policy") not in own
    tri = covered(predict.task_code("tri"))
    assert ("bench.backend.reconstruction", "known_pose_task") in tri
    assert ("bench.backend.reconstruction", "mapping_task") not in tri


def test_every_method_has_its_own_code_hash():
    from bench.harness.predict import method_code_hash
    from bench.vocabulary import CODE, METHODS, OWN_PIPELINE, TRACKS_PEER

    assert set(METHODS) <= set(CODE)
    hashes = {m: method_code_hash(m) for m in METHODS}
    assert all(hashes.values())
    colmap = [m for m in METHODS if METHODS[m].kind in (OWN_PIPELINE, TRACKS_PEER)]
    top_b = ["response", *(m for m in METHODS if METHODS[m].matcher)]  # the strongest B
    for same in (colmap, top_b):
        assert len(same) > 1 and len({hashes[m] for m in same}) == 1  # one function each
    shared = len(colmap) + len(top_b) - 2
    assert len(set(hashes.values())) == len(METHODS) - shared


def test_a_new_policy_or_a_methods_own_setting_changes_that_methods_rows_alone(tmp_path):
    from bench.frontend import plugins
    from bench.frontend.policies import POLICIES
    from bench.harness import predict
    from bench.harness.config import RunConfig
    from bench.vocabulary import CODE, METHODS

    cfg = RunConfig()
    names = [(m, t) for m in METHODS for t in ("tri", "sfm")]
    before = {n: predict.prediction_hash(cfg, *n) for n in names}
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
        predict.shared_code_hash.cache_clear()
        predict._own_code_hash.cache_clear()
        assert {n: predict.prediction_hash(cfg, *n) for n in names} == before
    finally:  # the registry as it was, for the other tests
        for registry in (METHODS, POLICIES, CODE, plugins.ORIGIN):
            registry.pop("cache-keys-new", None)
        plugins.load_module.cache_clear()
    looped = cfg.with_own("adaptive-loop", loop_rounds=3)
    changed = {m for m, t in names if predict.prediction_hash(looped, m, t) != before[(m, t)]}
    assert changed == {"adaptive-loop"}
    weights = tmp_path / "w.json"
    weights.write_text("{}")
    other = cfg.with_own("learned", learned_weights=str(weights))
    changed = {m for m, t in names if predict.prediction_hash(other, m, t) != before[(m, t)]}
    assert changed == {"learned"}


def test_each_task_and_stage_hashes_what_it_reads():
    """A task's rows depend on its own reconstruction and on the settings it reads: an nbv
    setting or a display field changes no tri row; the tasks' keys differ."""
    from bench.harness import predict
    from bench.harness.config import NbvConfig, RunConfig
    from bench.vocabulary import METHODS, deciding

    cfg = RunConfig()
    tri = {m: predict.prediction_hash(cfg, m, "tri") for m in METHODS}
    nbv = dataclasses.replace(cfg, nbv=NbvConfig(initial=4))
    assert {m: predict.prediction_hash(nbv, m, "tri") for m in METHODS} == tri
    assert tri["texture"] != predict.prediction_hash(cfg, "texture", "sfm")
    assert "label" not in deciding(METHODS["texture"])
    assert "matcher" in deciding(METHODS["texture"])


def test_a_methods_own_setting_does_not_bind_the_folder(tmp_path):
    from bench.binding import bind_results_dir, check_results_dir
    from bench.harness.config import RunConfig
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
    from bench.harness.config import RunConfig

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
    from bench.harness.config import RunConfig

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


def test_a_scenes_render_key_covers_its_own_generator_and_the_render_code_alone():
    from bench.render.entry import RENDER_CODE, render_code_hash
    from bench.scenes import catalog

    table = covered([*RENDER_CODE, catalog.generator_of("table")])
    assert ("bench.scenes.generators", "table") in table
    assert ("bench.camera", "write_colmap_rig") in table
    parts = covered(
        [*RENDER_CODE, catalog.generator_of("table")],
        cut=[g for g in catalog.generator_functions() if g is not catalog.generator_of("table")],
    )
    assert ("bench.scenes.generators", "facade") not in parts
    assert len({render_code_hash(s) for s in ("table", "facade", "corridor")}) == 3


def test_a_render_entry_under_an_aliased_key_is_current(tmp_path, monkeypatch):
    """A render entry under an older render key aliased to the current one is the scene's
    entry (nothing is rendered again); without the alias the current key's name."""
    from bench import codehash
    from bench.render.config import RenderConfig
    from bench.render.entry import entry_name, entry_names

    cfg = RenderConfig(width=96, height=72, spp=4, max_depth=2, variant="scalar_rgb")
    current = entry_name("table", 0, cfg, tmp_path)
    assert entry_names("table", 0, cfg, tmp_path) == [current]
    (tmp_path / "table-s0-0123456789ab").mkdir()
    aliases = tmp_path / "aliases.json"
    aliases.write_text(json.dumps([["0123456789ab", current.rpartition("-")[2]]]))
    monkeypatch.setattr(codehash, "ALIASES", aliases)
    assert entry_name("table", 0, cfg, tmp_path) == "table-s0-0123456789ab"
    assert entry_names("table", 0, cfg, tmp_path) == [current, "table-s0-0123456789ab"]
