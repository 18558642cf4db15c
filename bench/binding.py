"""A results folder bound to its settings: what it records of them (`config.json`,
`vocabulary.json`) and what a run, `bench plot` and `bench publish` check against them.

A row is finished when its `prediction_hash` (the settings its prediction reads, the
shared code, its task's and its method's own code and settings) and its `evaluation_hash`
(the code of the scoring) are the current ones, or older ones proven to give the same
values (`bench.codehash.accepted`): a row whose prediction is stale is computed again; a row whose evaluation
alone is stale is scored again from the unit's stored prediction. A results folder is bound to its shared settings
(`config.json`); its grid may grow (new scenes, seeds, methods, budgets, tasks run only
the new rows), a method's own settings may change (its rows alone run again), and only a
change of shared settings needs `--overwrite`. `bench publish` refuses to replace a
snapshot of other settings or another grid (`snapshot_differences`) unless `--replace`.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from bench import BenchError
from bench.files import write_text_atomic
from bench.results import CONFIG, DAMAGED, MODELS, RUNS, VOCABULARY
from bench.vocabulary import (
    KEY,
    Vocabulary,
    older_fields,
)


def read_vocabulary(results: Path) -> Vocabulary:
    """The vocabulary recorded in a results folder (`VOCABULARY`); one recorded by an older
    bench (`older_fields`) is refused, with `bench upgrade` as the remedy."""
    path = Path(results) / VOCABULARY
    try:
        text = path.read_text()
        older = older_fields(json.loads(text))
        if older:
            raise BenchError(
                f"{path} was written by an older bench (it lacks {', '.join(older)}); "
                f"`bench upgrade --results {results}` brings the folder up to date"
            )
        return Vocabulary.from_json(text)
    except FileNotFoundError:
        raise BenchError(
            f"{path} not found: these results were not written by this version of "
            "`bench run`; run it into the folder again"
        ) from None
    except (ValueError, KeyError, TypeError) as e:
        raise BenchError(f"{path} is unreadable ({type(e).__name__}: {e})") from None


def read_settings(results: Path) -> dict:
    """The settings a results folder is bound to (`CONFIG`'s `settings`)."""
    return json.loads((Path(results) / CONFIG).read_text())["settings"]


def flatten(d: dict, prefix: str = "") -> dict:
    """A nested dict's leaves by their dotted paths (`section.field`)."""
    out = {}
    for k, v in d.items():
        out |= flatten(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v}
    return out


OWN_SETTINGS = "methods"
"""The section of `config.json` holding each method's own settings: they decide that
method's rows alone (its `prediction_hash`) and do not bind the folder."""


def _shared(settings: dict) -> dict:
    return {k: v for k, v in settings.items() if k != OWN_SETTINGS}


def _settings(path: Path, remedy: str) -> dict:
    """The flattened settings a `config.json` holds (unreadable: one line with `remedy`)."""
    try:
        return flatten(json.loads(path.read_text())["settings"])
    except (ValueError, KeyError, TypeError) as e:
        raise BenchError(f"{path} is unreadable ({type(e).__name__}); {remedy}") from e


def _differing(there: dict, here: dict, now: str = "now") -> list[str]:
    """`key: value there, value now` for each key whose values differ."""
    keys = [k for k in sorted(set(there) | set(here)) if there.get(k) != here.get(k)]
    return [f"{k}: {there.get(k)!r} there, {here.get(k)!r} {now}" for k in keys]


def _new_at_default(older: dict, newer: dict, defaults: dict | None) -> set[str]:
    """The flattened settings `newer` has and `older` lacks, at their value in `defaults`:
    settings added since `older` was written, whose default is the behaviour before them."""
    default = flatten(_shared(json.loads(json.dumps(defaults or {}))))
    return {k for k, v in newer.items() if k not in older and k in default and default[k] == v}


def _renders(settings: dict) -> str:
    """What a run of these flattened settings is on: datasets render nothing."""
    return "datasets" if "render" in settings and settings["render"] is None else "rendered scenes"


def check_results_dir(
    results: Path, settings: dict, overwrite: bool, defaults: dict | None = None
) -> None:
    """Refuse to compute into `results` under other shared settings than the ones its
    `config.json` holds, naming each that differs, unless `overwrite` (a method's own
    settings may change: its rows alone are computed again; a setting the folder does not
    have yet may be at its value in `defaults`). Writes nothing."""
    settings = _shared(json.loads(json.dumps(settings)))  # tuples as lists, as stored
    stored_path = results / CONFIG
    if stored_path.exists() and not overwrite:
        stored = _settings(stored_path, "use --overwrite to start again")
        now = flatten(_shared(settings))
        # a stored setting this code no longer has (one that moved to its method), or a
        # method's own setting, decides nothing here; nor does a setting added since the
        # folder was made, at its default (a new setting's default is the behaviour before it)
        kind = [_renders(d) for d in (stored, now)]
        if kind[0] != kind[1]:
            raise BenchError(
                f"{results} holds a grid of {kind[0]}, and this run is on {kind[1]}; give "
                "another --results folder (or --overwrite to replace them)"
            )
        added = _new_at_default(stored, now, defaults)
        now = {k: v for k, v in now.items() if k not in added}
        differ = _differing({k: stored.get(k) for k in now}, now)
        if differ:
            raise BenchError(
                f"{results} holds results of other settings ({'; '.join(differ[:4])}); use "
                "--overwrite to replace them, or another --results folder"
            )


def _grid(runs_csv: Path) -> dict[str, set[str]]:
    """The values of each key column of a `runs.csv` (its grid)."""
    with runs_csv.open(newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: {r[k] for r in rows if r.get(k)} for k in KEY}


def snapshot_differences(
    results: Path, to: Path, defaults: Callable[[], dict] | None = None
) -> list[str]:
    """How the snapshot `to` differs from the results folder `results` in its settings
    (`config.json`; a setting one of them lacks is no difference where the other has it at
    its value in `defaults()`, called only then) and its grid (the values of each key
    column of `runs.csv`), one phrase each; none when `to` holds no snapshot."""
    differ = []
    there, here = Path(to) / CONFIG, Path(results) / CONFIG
    if there.is_file() and here.is_file():
        remedy = "use --replace to replace the snapshot"
        old, new = _settings(there, remedy), _settings(here, remedy)
        if set(old) != set(new) and defaults:
            default = defaults()
            same = _new_at_default(old, new, default) | _new_at_default(new, old, default)
            old, new = ({k: v for k, v in d.items() if k not in same} for d in (old, new))
        differ += _differing(old, new, "here")
    if (Path(to) / RUNS).is_file():
        old, new = _grid(Path(to) / RUNS), _grid(Path(results) / RUNS)
        for k in KEY:
            gone, added = sorted(old[k] - new[k]), sorted(new[k] - old[k])
            parts = [
                f"{', '.join(v[:5])}{' ...' if len(v) > 5 else ''} only {where}"
                for v, where in ((gone, "there"), (added, "here"))
                if v
            ]
            differ += [f"{k}: {' and '.join(parts)}"] if parts else []
    return differ


@contextmanager
def models_replaced(results: Path, overwrite: bool) -> Iterator[dict]:
    """With `overwrite`, the models (and stored predictions) of other settings moved aside
    before any unit writes its own; when the block ends they are removed if it bound the
    folder to the new settings (`state["bound"]`), else put back in place of whatever the
    refused run wrote: a run refused before its first rows loses nothing."""
    state = {"bound": False}
    models, aside = results / MODELS, results / f".models-replaced-{os.getpid()}"
    if not (overwrite and models.is_dir()):
        yield state
        return
    models.rename(aside)
    try:
        yield state
    finally:
        if state["bound"]:
            shutil.rmtree(aside)
        else:
            shutil.rmtree(models, ignore_errors=True)
            aside.rename(models)


def bind_results_dir(results: Path, settings: dict, vocab: Vocabulary, overwrite: bool) -> None:
    """Bind `results` to these settings (`config.json`: the shared ones bind it; each
    method's own, under `methods`, are the latest run's, earlier runs' kept for methods
    it does not set) as the first rows are computed, and record the vocabulary of its rows (`vocabulary.json`: this run's, keeping the entries
    of earlier runs for names it does not declare); with `overwrite`, the rows and
    vocabulary of other settings go first (their models went aside, `models_replaced`)."""
    if overwrite:
        for name in (RUNS, DAMAGED, VOCABULARY):
            (results / name).unlink(missing_ok=True)
    settings = json.loads(json.dumps(settings))
    try:
        earlier = json.loads((results / CONFIG).read_text())["settings"][OWN_SETTINGS]
    except (OSError, ValueError, KeyError, TypeError):
        earlier = {}
    if OWN_SETTINGS in settings and not overwrite:
        settings[OWN_SETTINGS] = earlier | settings[OWN_SETTINGS]
    write_text_atomic(results / CONFIG, json.dumps({"settings": settings}, indent=1))
    if (results / VOCABULARY).is_file():
        vocab = vocab.merged(read_vocabulary(results))
    write_text_atomic(results / VOCABULARY, vocab.to_json())
