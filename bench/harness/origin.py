"""A published snapshot's origin (`origin.json`): what made its rows, kept beside them so
that the snapshot stays a baseline whatever the code does after it.

Two questions, two answers (docs/results.md, "Baselines"). "Is this row stale?" is the
row key's (`bench.harness.keys.prediction_hash`: protocol and code, strict, for resuming
a working folder). "May this row be compared with mine?" is the origin's: a snapshot's
rows pair with rows of today's code where the protocol of each (method, task) is the same
(`bench.harness.keys.protocol_hash`: settings, the method's and task's deciding fields,
libraries, a module's own file) and the pixels are the same (the rows' `pixels`). Whether
today's code still computes the snapshot's values is `bench reproduce`'s question; the
modules that differ since the snapshot are named (`changed_modules`).

The origin is written once, when the snapshot is published (`bench publish`) or brought
up to date (`bench upgrade`), and only after every row's `prediction_hash` and
`evaluation_hash` are checked to be those of the commit it names (`snapshot_origin`):
nothing in it is taken on trust.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pandas as pd

from bench import ROOT, BenchError, __version__
from bench.codehash import code_record, git_source, library_versions
from bench.files import write_text_atomic
from bench.frontend.pools import POOLS
from bench.harness.keys import (
    PREDICTION_CODE,
    SCORING_CODE,
    evaluation_hash,
    prediction_hash,
    protocol_hash,
)
from bench.render.reference import read_manifest
from bench.results import ORIGIN
from bench.unit.config import RunConfig
from bench.unit.pooled import known
from bench.vocabulary import METHODS


def _pair(method: str, task: str) -> str:
    return f"{method} {task}"


def reference_hash() -> str:
    """The reference renders' content: the SHA-256 of their manifest's images (each file's
    SHA-256 and decoded pixels), not of the render keys it files them under (which a
    change of the render code's key moves while no image changes)."""
    manifest = read_manifest(ROOT / "reference")
    if manifest is None:
        return "absent"
    return hashlib.sha256(json.dumps(manifest["images"], sort_keys=True).encode()).hexdigest()


def snapshot_origin(rows: pd.DataFrame, cfg: RunConfig, commit: str, source=None) -> dict:
    """The origin of a snapshot's `rows`, computed under `cfg` by the code of `commit` (a
    commit of this repository, read with git; or the files as `source` reads them):
    refused in one line unless every row's `prediction_hash` and `evaluation_hash` are
    that code's."""
    source = source or git_source(commit)
    code = {"prediction": code_record(PREDICTION_CODE, source)}
    code["scoring"] = code_record(SCORING_CODE, source)
    protocols = {}
    for method, task in sorted(set(zip(rows["method"], rows["task"]))):
        try:
            known(method)
        except BenchError:
            raise BenchError(f"the snapshot's method {method!r} is not declared here") from None
        want = prediction_hash(cfg, method, task, code["prediction"]["code"])
        found = set(rows["prediction_hash"][(rows["method"] == method) & (rows["task"] == task)])
        if found != {want}:
            raise BenchError(
                f"{method}'s {task} rows were not computed by the code of "
                f"{commit} under the snapshot's settings (their "
                f"prediction_hash {', '.join(sorted(found))}, that code's {want}): publish "
                "a fresh run of that code"
            )
        protocols[_pair(method, task)] = protocol_hash(cfg, method, task)
    scored = evaluation_hash(code["scoring"]["code"])
    if set(rows["evaluation_hash"]) != {scored}:
        raise BenchError(
            f"the snapshot's rows were not scored by the code of {commit} "
            f"(evaluation_hash {', '.join(sorted(set(rows['evaluation_hash'])))}, its {scored})"
        )
    pools = {cfg.for_method(m).detector.detector for m in set(rows["method"])}
    return {
        "version": __version__,
        "commit": commit,
        "rows": len(rows),
        "reference": reference_hash(),
        "libraries": library_versions(models=True)
        | {k: v for p in sorted(pools) for k, v in POOLS[p].identity().items()},
        "code": {k: v["code"] for k, v in code.items()},
        "modules": code["prediction"]["modules"] | code["scoring"]["modules"],
        "protocols": protocols,
    }


def write_origin(folder: Path, origin: dict) -> None:
    """A snapshot's `origin.json` (`snapshot_origin`)."""
    write_text_atomic(Path(folder) / ORIGIN, json.dumps(origin, indent=1) + "\n")


def read_origin(folder: Path) -> dict:
    """A snapshot's origin, or one line saying how to record it."""
    path = Path(folder) / ORIGIN
    try:
        origin = json.loads(path.read_text())
        origin["protocols"], origin["modules"], origin["commit"]  # noqa: B018 (its fields)
        return origin
    except FileNotFoundError:
        raise BenchError(
            f"{path} not found: the snapshot records no origin; `bench upgrade --results "
            f"{folder}` records it (checked against the commit its manifest names)"
        ) from None
    except (ValueError, KeyError, TypeError) as e:
        raise BenchError(f"{path} is unreadable ({type(e).__name__}); restore it from git") from e


def header(origin: dict) -> str:
    """The line that names the baseline a comparison is made against."""
    return (
        f"bench {origin['version']}, commit {origin['commit'][:12]}, {origin['rows']} rows, "
        f"reference renders {origin['reference'][:12]}"
    )


def changed_modules(origin: dict) -> list[str]:
    """The modules of the rows' code that differ from the snapshot's (edited, added or
    gone), by name."""
    now = code_record(PREDICTION_CODE)["modules"] | code_record(SCORING_CODE)["modules"]
    then = origin["modules"]
    return sorted(m for m in set(now) | set(then) if now.get(m) != then.get(m))


def protocol_changes(origin: dict, cfg: RunConfig, pairs) -> dict[tuple[str, str], str]:
    """For each (method, task) of `pairs` whose protocol under `cfg` is not the snapshot's
    (or which the snapshot lacks), why its rows cannot be paired with today's."""
    out = {}
    for method, task in sorted(set(pairs)):
        then = origin["protocols"].get(_pair(method, task))
        if then is None:
            out[method, task] = f"the snapshot records no protocol of {method}'s {task} rows"
            continue
        try:
            same = method in METHODS and then == protocol_hash(cfg, method, task)
        except BenchError as e:  # its pool's packages are not installed here
            out[method, task] = f"{method}'s {task} rows: {e}"
            continue
        if not same:
            out[method, task] = (
                f"{method}'s {task} rows were computed under another protocol (settings, "
                "libraries or the fields that decide a row) than this checkout's"
            )
    return out
