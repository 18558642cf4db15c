"""The keys of a run's rows, computed by the harness when it plans a grid and handed to
each unit (`bench.unit.predict.Keys`): a row's `prediction_hash` (the settings, code and
libraries its prediction reads) and its `evaluation_hash` (the scoring's). The unit
(`bench.unit`) hashes nothing itself: what decides a row is there, what names it is here.
"""

from __future__ import annotations

from functools import partial

from bench.codehash import code_hash, library_versions
from bench.files import content_key
from bench.frontend import plugins
from bench.frontend.pools import POOLS
from bench.unit.config import RunConfig
from bench.unit.pooled import row_pool
from bench.unit.predict import Keys
from bench.unit.tasks import TASK_RUNNERS
from bench.vocabulary import METHODS, METRICS, TASKS, deciding

PREDICTION_CODE = ("bench.harness.execute",)
"""Where the code of every predicted row starts: the module that loads a unit's scene,
front ends and bags and stores its prediction with its kind's `store`; its import closure
(`bench.codehash.code_hash`) holds every method kind, task, policy and peer, the harness
glue between them and the scoring (an edit there predicts again: the key errs toward
computing, never toward reuse)."""


def _deciding(cfg: RunConfig, method: str, task: str) -> dict:
    """What decides a method's predicted rows of a task but the code: the settings the
    prediction reads (`RunConfig.prediction`), the fields of the method and task that
    decide a row (`bench.vocabulary.deciding`), the versions of the libraries it runs
    (`bench.codehash.library_versions`, the selection models', and its pool's packages,
    `Pool.identity`), the method's own settings and input files (the learned weights),
    and for a method from a module (`--policy-module`, an entry point) its module's
    content (`origin`)."""
    cfg = cfg.for_method(method)  # its pool's detector and matcher
    own = cfg.policy_config(method)
    runner = TASK_RUNNERS[task]
    declared = METHODS[method]
    origin = plugins.ORIGIN.get(method)
    return {
        "settings": cfg.prediction(runner.settings),
        "own": cfg.own(method),
        "method": deciding(declared),
        "task": {"name": task, "grant": runner.spec.grant, "maps": runner.maps},
        "libraries": library_versions(models=True) | POOLS[cfg.detector.detector].identity(),
        "inputs": plugins.files_hash(own.inputs()) if hasattr(own, "inputs") else "",
        "origin": plugins.files_hash([origin]) if origin else "",
    }


def prediction_hash(cfg: RunConfig, method: str, task: str, code: str | None = None) -> str:
    """The `prediction_hash` of a method's rows of a task: what decides them
    (`_deciding`) and the code (`PREDICTION_CODE`'s hash, or `code`: a published
    snapshot's, to check its rows against). Strict: it is how a working folder knows a
    row is current."""
    parts = _deciding(cfg, method, task)
    origin = parts.pop("origin")
    base = content_key(parts | {"code": code or code_hash(PREDICTION_CODE)})
    return content_key([base, origin]) if origin else base


def protocol_hash(cfg: RunConfig, method: str, task: str) -> str:
    """What decides a method's rows of a task but the code (`_deciding`, and the
    scoring's `_scoring_protocol`): two rows of the same protocol and pixels may be paired,
    whatever code computed each (a published snapshot's against this code's: `bench
    verdict`); whether the code still gives the same values is `bench reproduce`'s
    question."""
    return content_key([_deciding(cfg, method, task), _scoring_protocol()])


SCORING_CODE = ("bench.unit.evaluate",)
"""Where the scoring's code starts: the ground truth, each task's evaluation and what it
keeps, the readers of a stored prediction and the making of a row (its import closure,
`bench.codehash.code_hash`)."""


def _scoring_protocol() -> list:
    """What decides every row's scoring but the code: the versions of the libraries it
    runs and the fields of the tasks and metrics that decide a row's values."""
    declared = {
        "tasks": {n: deciding(t) for n, t in sorted(TASKS.items())},
        "metrics": {n: deciding(m) for n, m in sorted(METRICS.items())},
    }
    return [library_versions(), declared]


def evaluation_hash(code: str | None = None) -> str:
    """The `evaluation_hash` of every row: the scoring's code (`SCORING_CODE`'s hash, or
    `code`: a published snapshot's) and what else decides it (`_scoring_protocol`)."""
    return content_key([code or code_hash(SCORING_CODE), *_scoring_protocol()])[:12]


def unit_keys(cfg: RunConfig, method: str) -> Keys:
    """The keys of a method's units under `cfg` (what `bench.unit` is handed)."""
    return Keys(partial(prediction_hash, cfg, method), evaluation_hash(), row_pool(cfg, method))
