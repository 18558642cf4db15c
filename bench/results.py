"""The results folder: its layout (`Workspace`) and `runs.csv`, its one source of truth,
with the contract checked on every read.

Every row is validated: the file's structure (each line has as many fields as the header:
a row cut in the middle is caught), the required columns, the key values (scene, policy,
seed >= 0, budget >= 0, a known task and protocol), numbers where numbers belong, the
status (`ok` rows have their task's headline metrics, `failed` rows a reason). A damaged
file is one `BenchError` naming the file and the first bad row, and nothing is published
from it. Recovery: `bench run --set-aside-damaged` moves the damaged rows (as they were)
to `runs.damaged.csv` beside it and computes them again.

A row is finished when its `prediction_hash` (the shared settings and code, and its
method's own settings and code) and its `evaluation_hash` (the code of the scoring) are the
current ones: a row whose prediction is stale is computed again; a row whose evaluation
alone is stale is scored again from the unit's stored prediction. A results folder is bound to its shared settings
(`config.json`); its grid may grow (new scenes, seeds, policies, budgets, tasks run only
the new rows), a method's own settings may change (its rows alone run again), and only a
change of shared settings needs `--overwrite`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.files import write_text_atomic
from bench.vocabulary import HEADLINE, KEY, PROTOCOLS, VOCABULARY_FILE, Job, Unit, Vocabulary

HASHES = ("prediction_hash", "evaluation_hash")
TEXT_COLUMNS = ("scene", "policy", "task", "protocol", "render_key", *HASHES, "status")
TEXT_COLUMNS += ("failure", "invocation", "ground_truth")
REQUIRED = (*KEY, "render_key", *HASHES, "status", "failure", "invocation", "wall_ms")
DAMAGED = "runs.damaged.csv"
PREDICTION = "prediction"
"""A unit's stored prediction: `prediction.json` (written last) and `prediction.npz`."""


@dataclass(frozen=True)
class Workspace:
    """Where a run reads and writes: its results folder and the render cache."""

    results: Path
    renders: Path

    @property
    def runs_csv(self) -> Path:
        return self.results / "runs.csv"

    def unit_dir(self, unit: Unit) -> Path:
        """A unit's folder: its prediction, and the headline job's model at the top."""
        return (
            self.results / "models" / f"{unit.scene}-s{unit.seed}" / f"{unit.policy}-b{unit.budget}"
        )

    def model_dir(self, unit: Unit, job: Job) -> Path:
        """Where a job's model is exported: the headline task's folder is the unit's, any
        other task's a subfolder named after it; in it, the headline protocol's model at
        the top and any other protocol's in a subfolder named after the protocol (e.g.
        `twoview/`, `sfm/`, `sfm/twoview/`)."""
        folder = self.unit_dir(unit)
        if job.task != HEADLINE[0]:
            folder = folder / job.task
        return folder if job.protocol == HEADLINE[1] else folder / job.protocol


class DamagedRuns(BenchError):
    """`runs.csv` has damaged rows (`lines`: their line numbers, 1 = the header)."""

    def __init__(self, message: str, lines: list[int]):
        super().__init__(message)
        self.lines = lines


def _row_problem(row: dict[str, str], vocab: Vocabulary) -> str | None:
    """Why one row (raw strings) breaks the contract, or None."""
    for k in ("scene", "policy", "render_key", *HASHES, "invocation"):
        if not row[k]:
            return f"empty {k}"
    for k in ("seed", "budget"):
        try:
            if int(row[k]) < 0 or str(int(row[k])) != row[k]:
                raise ValueError
        except ValueError:
            return f"{k} {row[k]!r} is not a non-negative integer"
    if row["task"] not in vocab.tasks:
        return f"unknown task {row['task']!r}"
    if row["protocol"] not in PROTOCOLS:
        return f"unknown protocol {row['protocol']!r}"
    for k, v in row.items():
        if k not in TEXT_COLUMNS and v:
            try:
                float(v)
            except ValueError:
                return f"{k} {v!r} is not a number"
    if row["status"] == "failed":
        return None if row["failure"] else "a failed row without a reason"
    if row["status"] != "ok":
        return f"status {row['status']!r} is neither ok nor failed"
    needs = vocab.tasks[row["task"]].needs
    if row.get("ground_truth") in ("poses", "point cloud"):  # a dataset without pixel truth
        needs = tuple(k for k in needs if k != "acc_completeness_pct")
    for k in needs:
        if k not in row or not row[k] or not math.isfinite(float(row[k])):
            return f"an ok {row['task']} row without {k}"
    return None


def check_runs(
    path: Path, vocab: Vocabulary | None = None
) -> tuple[list[str], list[tuple[int, str]], list[tuple[int, str, str]]]:
    """(header, good rows as (line, text), damaged rows as (line, text, why)), the rows
    checked against `vocab` (default: the vocabulary recorded beside the file)."""
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError:
        raise DamagedRuns(f"{path} is damaged: it is not text", [1]) from None
    lines = text.splitlines()
    if not lines:
        raise DamagedRuns(f"{path} is damaged: it is empty", [1])
    header = next(csv.reader([lines[0]]))
    if "config_hash" in header and "prediction_hash" not in header:
        raise BenchError(
            f"{path} was written by an earlier bench (one config_hash per row, no stored "
            "predictions); compute it again with --overwrite, or use another --results folder"
        )
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise DamagedRuns(f"{path} is damaged: its header lacks {', '.join(missing)}", [1])
    vocab = vocab or Vocabulary.load(Path(path).parent)
    good, bad = [], []
    for n, line in enumerate(lines[1:], start=2):
        try:
            fields = next(csv.reader([line], strict=True))
        except (csv.Error, StopIteration) as e:
            bad.append((n, line, f"unparsable ({e})"))
            continue
        if len(fields) != len(header):
            bad.append((n, line, f"{len(fields)} fields, the header has {len(header)}"))
            continue
        why = _row_problem(dict(zip(header, fields)), vocab)
        (bad.append((n, line, why)) if why else good.append((n, line)))
    return header, good, bad


def read_runs(path: Path, vocab: Vocabulary | None = None) -> pd.DataFrame:
    """Every row of a valid `runs.csv`, checked against `vocab` (default: the vocabulary
    recorded beside it); a damaged one is a `DamagedRuns` error."""
    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path} not found: run `bench run` first (or pass --results DIR)")
    header, good, bad = check_runs(path, vocab)
    if bad:
        n, _, why = bad[0]
        raise DamagedRuns(
            f"{path} is damaged: row at line {n}: {why} ({len(bad)} damaged row(s)); nothing "
            "is published from it. `bench run --set-aside-damaged` moves them to "
            f"{DAMAGED} and computes them again",
            [b[0] for b in bad],
        )
    if not good:
        raise BenchError(f"{path} holds no runs")
    return _frame(header, good)


def _frame(header: list[str], good: list[tuple[int, str]]) -> pd.DataFrame:
    text = "\n".join([",".join(header)] + [line for _, line in good])
    return pd.read_csv(
        io.StringIO(text),
        dtype={c: str for c in TEXT_COLUMNS},
        keep_default_na=False,
        na_values=[""],
    ).assign(failure=lambda d: d["failure"].fillna(""))


def set_aside_damaged(path: Path, vocab: Vocabulary) -> int:
    """Move the damaged rows of `runs.csv` to `runs.damaged.csv` (appended, as they were);
    how many. A file whose header is damaged is set aside whole."""
    path = Path(path)
    aside = path.with_name(DAMAGED)
    try:
        header, good, bad = check_runs(path, vocab)
    except DamagedRuns:
        text = path.read_text(errors="replace")
        write_text_atomic(aside, (aside.read_text() if aside.exists() else "") + text)
        path.unlink()
        return max(len(text.splitlines()) - 1, 1)
    if bad:
        kept = "\n".join([",".join(header)] + [line for _, line in good]) + "\n"
        prior = aside.read_text() if aside.exists() else ",".join(header) + "\n"
        write_text_atomic(aside, prior + "\n".join(line for _, line, _ in bad) + "\n")
        write_text_atomic(path, kept)
    return len(bad)


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        out |= _flatten(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v}
    return out


OWN_SETTINGS = "methods"
"""The section of `config.json` holding each method's own settings: they decide that
method's rows alone (its `prediction_hash`) and do not bind the folder."""


def _shared(settings: dict) -> dict:
    return {k: v for k, v in settings.items() if k != OWN_SETTINGS}


def check_results_dir(results: Path, settings: dict, overwrite: bool) -> None:
    """Refuse to compute into `results` under other shared settings than the ones its
    `config.json` holds, naming each that differs, unless `overwrite` (a method's own
    settings may change: its rows alone are computed again). Writes nothing."""
    settings = _shared(json.loads(json.dumps(settings)))  # tuples as lists, as stored
    stored_path = results / "config.json"
    if stored_path.exists() and not overwrite:
        try:
            stored = _flatten(_shared(json.loads(stored_path.read_text())["settings"]))
        except (ValueError, KeyError, TypeError) as e:
            raise BenchError(
                f"{stored_path} is unreadable ({type(e).__name__}); use --overwrite to start again"
            ) from e
        now = _flatten(settings)
        # a stored setting this code no longer has (one that moved to its method) decides nothing
        differ = [k for k in sorted(now) if stored.get(k) != now[k]]
        if differ:
            shown = "; ".join(
                f"{k}: {stored.get(k)!r} there, {now.get(k)!r} now" for k in differ[:4]
            )
            raise BenchError(
                f"{results} holds results of other settings ({shown}); use --overwrite to "
                "replace them, or another --results folder"
            )


@contextmanager
def models_replaced(results: Path, overwrite: bool) -> Iterator[dict]:
    """With `overwrite`, the models (and stored predictions) of other settings moved aside
    before any unit writes its own; when the block ends they are removed if it bound the
    folder to the new settings (`state["bound"]`), else put back in place of whatever the
    refused run wrote: a run refused before its first rows loses nothing."""
    state = {"bound": False}
    models, aside = results / "models", results / f".models-replaced-{os.getpid()}"
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
        for name in ("runs.csv", DAMAGED, VOCABULARY_FILE):
            (results / name).unlink(missing_ok=True)
    settings = json.loads(json.dumps(settings))
    try:
        earlier = json.loads((results / "config.json").read_text())["settings"][OWN_SETTINGS]
    except (OSError, ValueError, KeyError, TypeError):
        earlier = {}
    if OWN_SETTINGS in settings and not overwrite:
        settings[OWN_SETTINGS] = earlier | settings[OWN_SETTINGS]
    write_text_atomic(results / "config.json", json.dumps({"settings": settings}, indent=1))
    if (results / VOCABULARY_FILE).is_file():
        vocab = vocab.merged(Vocabulary.load(results))
    write_text_atomic(results / VOCABULARY_FILE, vocab.to_json())
