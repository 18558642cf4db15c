"""Cache keys as narrow as what they protect: a docstring or comment changes no hash, an
edit inside a stage's code changes that stage's hash alone, a method's rows depend on its
own code and settings, a scene's render key on its own generator."""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
import textwrap

import pytest

from bench import BenchError
from bench.codehash import code_hash, covered, object_digest

SHARED = '''
"""Helpers of the synthetic stage."""

SCALE = 2  # the scale


def helper(x):
    """Doubles."""
    return SCALE * x


def colmap_io(path):
    """Not reached by the stage."""
    return open(path).read()


def lazy(x):
    return x * 3
'''

STAGE = '''
"""A synthetic stage."""

from ckpkg import shared
from ckpkg.shared import helper


def run(x):
    """Runs."""
    return helper(x) + shared.SCALE + method_a(x) + late(x)


def late(x):
    from ckpkg.shared import lazy

    return lazy(x)


def method_a(x):
    return x + 1


def method_b(x):
    return x - 1
'''


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """A package of two modules written to tmp_path and imported; `edit(module, old,
    new)` rewrites one of its files (the imported modules are hashed from their files)."""
    root = tmp_path / "ckpkg"
    root.mkdir()
    (root / "__init__.py").write_text("")
    (root / "shared.py").write_text(SHARED)
    (root / "stage.py").write_text(STAGE)
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("ckpkg", "ckpkg.shared", "ckpkg.stage"):
        sys.modules.pop(name, None)
    stage = importlib.import_module("ckpkg.stage")

    def edit(module: str, old: str, new: str) -> None:
        path = root / f"{module}.py"
        text = path.read_text()
        assert old in text
        path.write_text(text.replace(old, new))

    yield stage, edit
    for name in ("ckpkg", "ckpkg.shared", "ckpkg.stage"):
        sys.modules.pop(name, None)


def _hash(stage, cut=()):
    return code_hash([stage.run], cut=cut, packages=("ckpkg",))


@pytest.mark.parametrize(
    "module, old, new",
    [
        ("shared", '"""Doubles."""', '"""Twice its argument, a corrected docstring."""'),
        ("shared", "# the scale", "# the scale factor, a longer comment"),
        ("stage", '"""A synthetic stage."""', '"""A synthetic stage, documented anew."""'),
        ("stage", "def run(x):", "\n\ndef run(x):  # a comment and blank lines"),
        ("shared", "def colmap_io(path):", "def colmap_io(path, mode='r'):"),  # not reached
        ("stage", "return x - 1", "return x - 2"),  # method_b: not reached
        ("stage", "\ndef method_b", "\ndef method_c(x):\n    return 0\n\n\ndef method_b"),  # new
    ],
)
def test_docstrings_comments_and_unreached_code_change_no_hash(pkg, module, old, new):
    stage, edit = pkg
    before = _hash(stage)
    edit(module, old, new)
    assert _hash(stage) == before


@pytest.mark.parametrize(
    "module, old, new",
    [
        ("shared", "return SCALE * x", "return SCALE * x + 1"),  # a function the stage calls
        ("shared", "SCALE = 2", "SCALE = 3"),  # a constant it reads, through the module
        ("stage", "return x + 1", "return x + 10"),  # a function of its own module
        ("shared", "return x * 3", "return x * 4"),  # imported inside a function
    ],
)
def test_an_edit_in_a_stage_closure_changes_its_hash(pkg, module, old, new):
    stage, edit = pkg
    before = _hash(stage)
    edit(module, old, new)
    assert _hash(stage) != before


def test_a_cut_function_belongs_to_its_own_hash(pkg):
    """A method's function cut out of the shared hash: editing it changes its own hash
    and not the shared one."""
    stage, edit = pkg
    shared, own = _hash(stage, cut=[stage.method_a]), code_hash([stage.method_a])
    edit("stage", "return x + 1", "return x + 10")
    assert _hash(stage, cut=[stage.method_a]) == shared
    assert code_hash([stage.method_a]) != own


def test_a_digest_ignores_docstrings_and_comments(pkg):
    stage, edit = pkg
    before = object_digest(stage)
    edit("stage", '"""Runs."""', '"""Runs the stage (a longer docstring)."""  # and a comment')
    assert object_digest(stage) == before
    edit("stage", "return x + 1", "return x + 10")
    assert object_digest(stage) != before


def test_the_shared_prediction_code_is_derived_and_leaves_the_methods_and_scoring_out():
    from bench.frontend import policies
    from bench.harness import predict

    parts = covered(predict.SHARED_CODE, cut=(predict.SCORING, *predict._method_roots()))
    modules = {m for m, _ in parts}
    assert "bench.frontend.colmap_model" in modules  # missing from the hand-kept lists
    assert {"bench.frontend.signals", "bench.backend.reconstruction"} <= modules
    assert not any(m.startswith("bench.evaluation") for m in modules)
    assert ("bench.frontend.policies", "adaptive_policy") not in parts
    assert ("bench.frontend.policies", "select") in parts  # the contract every policy meets
    assert ("bench.frontend.feedback", "feedback_select") not in parts
    own = covered([policies.POLICIES["adaptive"]], cut=predict._method_roots("adaptive"))
    assert ("bench.frontend.policies", "capped_greedy") in own
    assert ("bench.frontend.policies", "random_policy") not in own


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
    names = [m for m in METHODS]
    before = {m: predict.prediction_hash(cfg, m) for m in names}
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
        assert {m: predict.prediction_hash(cfg, m) for m in names} == before
    finally:  # the registry as it was, for the other tests
        for registry in (METHODS, POLICIES, CODE, plugins.ORIGIN):
            registry.pop("cache-keys-new", None)
        plugins.load_module.cache_clear()
    looped = cfg.with_own("adaptive-loop", loop_rounds=3)
    changed = {m for m in names if predict.prediction_hash(looped, m) != before[m]}
    assert changed == {"adaptive-loop"}
    weights = tmp_path / "w.json"
    weights.write_text("{}")
    other = cfg.with_own("learned", learned_weights=str(weights))
    assert {m for m in names if predict.prediction_hash(other, m) != before[m]} == {"learned"}


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
