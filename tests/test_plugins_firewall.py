"""The ground-truth firewall of policy modules: a syntax check that reads imports and
calls (not docstrings), and a guard while a module loads and while a policy selects."""

from __future__ import annotations

import importlib

import pytest

from bench import BenchError
from bench.frontend import plugins
from bench.frontend.policies import POLICIES, PolicyConfig, PolicyFailed
from bench.frontend.selection import select_views
from bench.vocabulary import METHODS
from tests.test_failures import _input

HEAD = "import importlib\nimport numpy as np\nfrom bench.frontend.policies import policy\n"


def _module(tmp_path, body: str, name: str = "mine"):
    path = tmp_path / f"{name}.py"
    path.write_text(HEAD + body)
    return path


@pytest.mark.parametrize(
    "body, why",
    [
        (
            'importlib.import_module("bench.evaluation." + "lay" + "ers")\n',
            "it imports bench.evaluation.layers (line 4)",
        ),
        ("name = 'bench.harness'\nimportlib.import_module(name)\n", "by a computed name (line 5)"),
        ("__import__('bench.' + 'scenes')\n", "it imports bench.scenes (line 4)"),
        ("import sys\nsys.modules.get('x')\n", "it reads sys.modules (line 5)"),
        ("from sys import modules\n", "it reads sys.modules (line 4)"),
    ],
)
def test_a_module_importing_a_stage_by_a_built_name_is_refused(tmp_path, body, why):
    with pytest.raises(BenchError, match="broke the contract rule 'no ground truth'") as e:
        plugins.load_module(str(_module(tmp_path, body)))
    assert why in str(e.value)


def test_a_docstring_naming_ground_truth_files_is_not_refused(tmp_path):
    body = (
        '@policy("honest")\ndef honest(inp, budget, rng, cfg):\n'
        '    """Never reads gt_00.npz, meta.json or ground_truth/."""\n'
        "    return np.arange(budget)\n"
    )
    try:
        assert plugins.load_module(str(_module(tmp_path, body))) == ("honest",)
    finally:
        POLICIES.pop("honest", None), METHODS.pop("honest", None)


RUNTIME = {
    "opens": (
        "    name = ''.join(['g', 't_0', '0.n', 'pz'])\n"
        "    open(inp.view.name.replace('v.png', name))\n",
        "it opened gt_00.npz",
    ),
    "imports": (
        "    load = getattr(importlib, 'import_' + 'module')\n    load('bench.evaluation')\n",
        "it imported bench.evaluation",
    ),
}


@pytest.mark.parametrize("case", list(RUNTIME))
def test_a_policy_reaching_for_ground_truth_at_run_time_fails_naming_the_rule(tmp_path, case):
    body, what = RUNTIME[case]
    name = f"sneaky-{case}"
    code = f'@policy("{name}")\ndef sneaky(inp, budget, rng, cfg):\n{body}    return np.arange(budget)\n'
    plugins.load_module(str(_module(tmp_path, code, case)))
    try:
        with pytest.raises(PolicyFailed) as e:
            select_views(name, [_input()], 5, 0, PolicyConfig(), match=None)
    finally:
        POLICIES.pop(name), METHODS.pop(name)
    assert "'no ground truth'" in str(e.value) and what in str(e.value)
    assert f"{tmp_path / case}.py:" in str(e.value)
    importlib.import_module("bench.evaluation")  # the guard is lifted after the call
    with pytest.raises(FileNotFoundError):
        open(tmp_path / "gt_00.npz")
