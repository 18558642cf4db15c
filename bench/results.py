"""The results folder: its layout (`Workspace`) and `runs.csv`, its one source of truth,
with the contract checked on every read.

Every row is validated: the file's structure (each line has as many fields as the header:
a row cut in the middle is caught), the required columns, the key values (scene, policy,
seed >= 0, budget >= 0, a known task and protocol; no key twice), numbers where numbers
belong, the status (`ok` rows have their task's headline metrics, `failed` rows a reason).
Each row also carries its own integrity: every number lies in its declared range
(`bench.vocabulary.Metric.range`), and `row_checksum` (last) is a hash of the row's values as
written, so a value edited by hand is caught (against accidents, not an attacker with the
code). A damaged file is one `BenchError` naming the file and the first bad row (line and
key) and the remedy, and no table, figure or snapshot is written from it. Recovery: `bench
run --reevaluate` scores rows whose values were altered again; `bench run --set-aside-damaged` moves the damaged rows (as
they were) to `runs.damaged.csv` beside it and computes them again. A file written before
rows carried checksums is refused in one line; `bench run --reevaluate` scores its rows
again and records them with checksums.

Rows are appended to `runs.csv` as their units finish (`append_runs`); the file is rewritten
whole only to drop rows a run computes again (once, before its first rows) or to add a
column its header lacks. Readers get the rows sorted by their key, with `reference_maps`
derived from the stock-COLMAP rows (`mark_reference`).

A row is finished when its `prediction_hash` (the shared settings and code, and its
method's own settings and code) and its `evaluation_hash` (the code of the scoring) are the
current ones: a row whose prediction is stale is computed again; a row whose evaluation
alone is stale is scored again from the unit's stored prediction. A results folder is bound to its shared settings
(`config.json`); its grid may grow (new scenes, seeds, methods, budgets, tasks run only
the new rows), a method's own settings may change (its rows alone run again), and only a
change of shared settings needs `--overwrite`. One bench process at a time writes a folder
(`holding`): a run, `bench plot` or `bench publish`; another is refused in one line while
it does. `bench publish` refuses to replace a snapshot of other settings or another grid
(`snapshot_differences`) unless `--replace`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import numbers
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.files import content_key, exclusive, write_text_atomic
from bench.vocabulary import (
    HEADLINE,
    KEY,
    PROTOCOLS,
    REFERENCE_MAPS,
    REFERENCE_MIN_MAA,
    REFERENCE_PEER,
    Job,
    Unit,
    Vocabulary,
    older_fields,
)

HASHES = ("prediction_hash", "evaluation_hash")
ROW_CHECKSUM = "row_checksum"
"""The last column: a hash of the row's other values as written (`row_checksum`)."""
TEXT_COLUMNS = ("scene", "method", "task", "protocol", "render_key", *HASHES, "status")
TEXT_COLUMNS += ("failure", "invocation", "ground_truth", "pairs_rule", "bag", ROW_CHECKSUM)
REQUIRED = (*KEY, "render_key", *HASHES, "status", "failure", "invocation", "wall_ms")
OLD_METHOD = "policy"
"""The `method` column's name before 0.3.0 (`bench upgrade` renames it)."""

# The results folder's layout: every file a run and its report write, named here alone
# (tests/test_layout.py fails where another module spells one).
RUNS = "runs.csv"
DAMAGED = "runs.damaged.csv"
"""Damaged rows set aside (`set_aside_damaged`)."""
CONFIG = "config.json"
"""The settings the folder is bound to (`bind_results_dir`)."""
VOCABULARY = "vocabulary.json"
"""The methods, tasks and metrics its rows were computed under (`read_vocabulary`)."""
MANIFEST = "manifest.json"
"""Versions, machine, settings and the invocations that computed the rows."""
PAGE = "README.md"
"""The results page (`bench.report.page`)."""
GALLERY = "scenes.png"
"""The contact sheet of the scenes (`bench gallery`)."""
LOCK = ".bench-run.lock"
MODELS = "models"
"""One folder per unit (`Workspace.unit_dir`): its prediction and models."""
PREDICTION = "prediction"
"""A unit's stored prediction: `prediction.json` (written last) and `prediction-<grant>.npz`
(`bench.harness.predict`)."""
LOOP = "loop.json"
"""Beside the model of a multi-view policy: its rounds."""
POINT_ERRORS = "point_errors.csv"
"""Beside a tri model: each point's distance to the ground-truth surface (Figure 2)."""
TABLES = (
    "table1.csv",
    "table1_twoview.csv",
    "table2.csv",
    "paired.csv",
    "paired_sfm.csv",
    "table_scenes.csv",
    "frontend_cost.csv",
    "table3.csv",
)
"""The report's tables (`bench.report.tables`; Table 3, of the nbv task: `bench.report.nbv`)."""
TABLE1, TABLE1_TWOVIEW, TABLE2, PAIRED, PAIRED_SFM, TABLE_SCENES, FRONTEND_COST, TABLE3 = TABLES
# The equal-keypoint comparison (`bench.report.tables.equal_keypoints`), where it ran.
TABLE1_EQUAL = "table1_equal.csv"
FIGURES = ("figure2", "figure3", "figure_budget", "figure_views")
"""The report's figures, without their suffix (`.png`; Figure 3 also `.pdf`)."""
FIGURE2, FIGURE3, FIGURE_BUDGET, FIGURE_VIEWS = FIGURES
TRANSFER, TRANSFER_RANKS, FIGURE_TRANSFER = "transfer.csv", "transfer_ranks.csv", "figure_transfer"
"""A dataset folder's ranking against rendered folders (`bench.report.transfer`)."""


def png(figure: str) -> str:
    return f"{figure}.png"


def table1_of(scene: str) -> str:
    """A dataset folder's Table 1 of one of its datasets."""
    return f"table1-{scene}.csv"


@dataclass(frozen=True)
class Workspace:
    """Where a run reads and writes: its results folder and the render cache."""

    results: Path
    renders: Path

    @property
    def runs_csv(self) -> Path:
        return self.results / RUNS

    def unit_dir(self, unit: Unit) -> Path:
        """A unit's folder: its prediction, and the headline job's model at the top."""
        return (
            self.results / MODELS / f"{unit.scene}-s{unit.seed}" / f"{unit.method}-b{unit.budget}"
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


def runs_file(path: Path) -> Path:
    """`path` (a `runs.csv`), or one line saying that there is none."""
    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path} not found: run `bench run` first (or pass --results DIR)")
    return path


def holding(folder: Path, reading: bool = False):
    """Hold a results folder (or snapshot) for a run, `bench plot` or `bench publish`:
    another bench process is refused in one line while one does. `reading`: a folder that
    cannot be written is read without the lock (no run can write there either)."""
    folder = Path(folder)
    if reading and folder.is_dir() and not os.access(folder, os.W_OK):
        return nullcontext()
    return exclusive(folder / LOCK, f"results folder {folder}")


def row_checksum(fields: dict[str, str]) -> str:
    """The hash of a row's values as written (its empty fields and checksum left out, so
    that a column added to the header changes nothing)."""
    return content_key({k: v for k, v in fields.items() if v and k != ROW_CHECKSUM})


def _row_problem(row: dict[str, str], vocab: Vocabulary) -> str | None:
    """Why one row (raw strings) breaks the contract, or None."""
    for k in ("scene", "method", "render_key", *HASHES, "invocation"):
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


def _altered(row: dict[str, str], vocab: Vocabulary) -> str | None:
    """Why the values of a well-formed row are not the ones written (a number outside its
    declared range, or values that do not match the row's checksum), or None."""
    for k, v in row.items():
        if k in TEXT_COLUMNS or k in KEY or not v:
            continue
        bounds = vocab.range_of(k)
        if bounds is None:
            return f"{k} is no declared metric (bench.vocabulary.declare_metric)"
        lo, hi = bounds
        x = float(v)
        if not math.isfinite(x) or x < lo or (hi is not None and x > hi):
            return f"{k} {v} is outside its range [{lo:g}, {'inf' if hi is None else f'{hi:g}'}]"
    if ROW_CHECKSUM not in row:
        return f"no {ROW_CHECKSUM} (written before rows carried checksums)"
    if row[ROW_CHECKSUM] != row_checksum(row):
        return f"its values do not match its {ROW_CHECKSUM} (edited by hand?)"
    return None


def _key_of(row: dict[str, str]) -> tuple:
    return tuple(int(row[k]) if k in ("seed", "budget") else row[k] for k in KEY)


def _key_text(header: list[str], line: str) -> str:
    """` (scene, seed s, method, budget b, task, protocol)` of a row's line, if readable."""
    try:
        row = dict(zip(header, next(csv.reader([line]))))
        return " ({}, seed {}, {}, budget {}, {}, {})".format(*(row[k] for k in KEY))
    except (csv.Error, StopIteration, KeyError):
        return ""


def check_runs(
    path: Path, vocab: Vocabulary | None = None
) -> tuple[list[str], list[tuple[int, str]], list[tuple[int, str, str, bool]]]:
    """(header, good rows as (line, text), bad rows as (line, text, why, altered)), the
    rows checked against `vocab` (default: the vocabulary recorded beside the file);
    `altered`: a well-formed row whose values are not the ones written (`_altered`)."""
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError:
        raise DamagedRuns(f"{path} is damaged: it is not text", [1]) from None
    lines = text.splitlines()
    if not lines:
        raise DamagedRuns(f"{path} is damaged: it is empty", [1])
    header = next(csv.reader([lines[0]]))
    if OLD_METHOD in header and "method" not in header:
        raise BenchError(
            f"{path} was written by an older bench (its `{OLD_METHOD}` column is now "
            f"`method`); `bench upgrade --results {Path(path).parent}` renames it"
        )
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise DamagedRuns(f"{path} is damaged: its header lacks {', '.join(missing)}", [1])
    vocab = vocab or read_vocabulary(Path(path).parent)
    good, bad, seen = [], [], {}
    for n, line in enumerate(lines[1:], start=2):
        try:
            fields = next(csv.reader([line], strict=True))
        except (csv.Error, StopIteration) as e:
            bad.append((n, line, f"unparsable ({e})", False))
            continue
        if len(fields) != len(header):
            bad.append((n, line, f"{len(fields)} fields, the header has {len(header)}", False))
            continue
        row = dict(zip(header, fields))
        why = _row_problem(row, vocab)
        if why is None and _key_of(row) in seen:
            why = f"its key is the key of line {seen[_key_of(row)]}"
        if why:
            bad.append((n, line, why, False))
            continue
        seen[_key_of(row)] = n
        why = _altered(row, vocab)
        (bad.append((n, line, why, True)) if why else good.append((n, line)))
    return header, good, bad


def read_runs(
    path: Path, vocab: Vocabulary | None = None, keep_altered: bool = False
) -> pd.DataFrame:
    """Every row of a valid `runs.csv`, checked against `vocab` (default: the vocabulary
    recorded beside it), sorted by key, with `reference_maps`; a damaged one is a
    `DamagedRuns` error. `keep_altered` (for `bench run --reevaluate`, which scores them
    again): rows whose values were altered are kept, marked in an `altered` column."""
    path = runs_file(path)
    header, good, bad = check_runs(path, vocab)
    if ROW_CHECKSUM not in header and not keep_altered:
        raise BenchError(
            f"{path} was written before rows carried checksums; `bench run --reevaluate` "
            "(with the grid it holds) scores its rows again and records them"
        )
    damaged = [b for b in bad if not (keep_altered and b[3])]
    if damaged:
        n, line, why, _ = damaged[0]
        folder = f"--results {path.parent}"
        remedy = (
            f"`bench run --set-aside-damaged {folder}` moves them to {DAMAGED} and computes "
            "them again"
        )
        if any(b[3] for b in damaged):
            remedy = (
                f"`bench run --reevaluate {folder}` (with the grid it holds) scores altered "
                f"rows again from their stored predictions, or {remedy}"
            )
        raise DamagedRuns(
            f"{path} is damaged: row at line {n}{_key_text(header, line)}: {why} "
            f"({len(damaged)} damaged row(s)); to recover, {remedy}",
            [b[0] for b in damaged],
        )
    altered = [(n, line) for n, line, _, _ in bad]
    if not good and not altered:
        raise BenchError(f"{path} holds no runs")
    df = _frame(header, good + altered)
    if keep_altered:
        df["altered"] = [False] * len(good) + [True] * len(altered)
    df = mark_reference(df, vocab or read_vocabulary(path.parent))
    return df.sort_values(list(KEY), kind="stable", ignore_index=True)


def _frame(header: list[str], good: list[tuple[int, str]]) -> pd.DataFrame:
    text = "\n".join([",".join(header)] + [line for _, line in good])
    return pd.read_csv(
        io.StringIO(text),
        dtype={c: str for c in TEXT_COLUMNS},
        keep_default_na=False,
        na_values=[""],
    ).assign(failure=lambda d: d["failure"].fillna(""))


def mark_reference(table: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """`REFERENCE_MAPS` on every row: whether stock COLMAP with all features maps the row's
    (scene, seed) in the tasks with the exclusion rule (`Task.exclusion_reference`; in
    every one of them, under the headline protocol; see the vocabulary)."""
    if not {"views", "registered_views", "maa"} <= set(table):
        return table
    ref = table[
        (table["method"] == REFERENCE_PEER)
        & table["task"].isin(vocab.exclusion_tasks)
        & (table["protocol"] == HEADLINE[1])
    ]
    maps: dict[tuple, int] = {}
    for r in ref.itertuples():
        if pd.notna(r.registered_views):
            ok = int(r.registered_views >= r.views and r.maa >= REFERENCE_MIN_MAA)
            maps[r.scene, r.seed] = min(ok, maps.get((r.scene, r.seed), 1))
    cells = zip(table["scene"], table["seed"])
    return table.assign(**{REFERENCE_MAPS: [maps.get(c) for c in cells]})


def _text(value) -> str:
    """A value as `runs.csv` holds it: numbers exactly (repr), NaN and None empty, text on
    one line."""
    if value is None:
        return ""
    if isinstance(value, str):
        return " ".join(value.splitlines())
    if isinstance(value, numbers.Integral):
        return str(int(value))
    x = float(value)
    return "" if math.isnan(x) else repr(x)


def _csv_lines(rows: list[list[str]]) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows)
    return out.getvalue()


def append_runs(path: Path, rows: list[dict], vocab: Vocabulary) -> None:
    """Append a unit's rows to `runs.csv`, each with its checksum, once they pass the checks
    a reader makes (a row that does not is a bug: one `BenchError` naming it). The first
    rows create the file with its header; a row with a column the header lacks rewrites
    the file once with the column added (every checksum stays valid)."""
    path = Path(path)
    texts = [{k: _text(v) for k, v in r.items()} for r in rows]
    for t in texts:
        t[ROW_CHECKSUM] = row_checksum(t)
        full = dict.fromkeys(REQUIRED, "") | t
        why = _row_problem(full, vocab) or _altered(full, vocab)
        if why:
            key = ", ".join(t.get(k, "?") for k in KEY)
            raise BenchError(f"a computed row ({key}) breaks the runs.csv contract: {why}")
    header = []
    if path.is_file():
        with path.open() as f:
            header = next(csv.reader([f.readline()]))
    new = [k for k in dict.fromkeys(k for t in texts for k in t) if k not in header]
    if not new:
        text = _csv_lines([[t.get(k, "") for k in header] for t in texts])
        with path.open("rb+") as f:
            f.seek(-1, os.SEEK_END)
            ended = f.read(1) == b"\n"  # a write cut just before its last newline
            f.seek(0, os.SEEK_END)
            f.write((text if ended else "\n" + text).encode())
        return
    old = []
    if header:
        old = [dict(zip(header, f)) for f in csv.reader(path.read_text().splitlines()[1:])]
    header = [k for k in header if k != ROW_CHECKSUM] + [k for k in new if k != ROW_CHECKSUM]
    header.append(ROW_CHECKSUM)
    body = [[t.get(k, "") for k in header] for t in old + texts]
    write_text_atomic(path, _csv_lines([header, *body]))


def keep_runs(path: Path, keys: set[tuple]) -> None:
    """Keep the rows of `keys` alone in `runs.csv` (before a run appends the rows it
    computes again); the file is rewritten only if it holds others."""
    path = Path(path)
    if not path.is_file():
        return
    header, good, bad = check_runs(path)
    kept = [
        line for _, line in good if _key_of(dict(zip(header, next(csv.reader([line]))))) in keys
    ]
    if len(kept) == len(good) + len(bad):
        return
    if kept:
        write_text_atomic(path, "\n".join([",".join(header), *kept]) + "\n")
    else:
        path.unlink()


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
        write_text_atomic(aside, prior + "\n".join(b[1] for b in bad) + "\n")
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


def _settings(path: Path, remedy: str) -> dict:
    """The flattened settings a `config.json` holds (unreadable: one line with `remedy`)."""
    try:
        return _flatten(json.loads(path.read_text())["settings"])
    except (ValueError, KeyError, TypeError) as e:
        raise BenchError(f"{path} is unreadable ({type(e).__name__}); {remedy}") from e


def _differing(there: dict, here: dict, now: str = "now") -> list[str]:
    """`key: value there, value now` for each key whose values differ."""
    keys = [k for k in sorted(set(there) | set(here)) if there.get(k) != here.get(k)]
    return [f"{k}: {there.get(k)!r} there, {here.get(k)!r} {now}" for k in keys]


def _new_at_default(older: dict, newer: dict, defaults: dict | None) -> set[str]:
    """The flattened settings `newer` has and `older` lacks, at their value in `defaults`:
    settings added since `older` was written, whose default is the behaviour before them."""
    default = _flatten(_shared(json.loads(json.dumps(defaults or {}))))
    return {k for k, v in newer.items() if k not in older and k in default and default[k] == v}


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
        now = _flatten(_shared(settings))
        # a stored setting this code no longer has (one that moved to its method), or a
        # method's own setting, decides nothing here; nor does a setting added since the
        # folder was made, at its default (a new setting's default is the behaviour before it)
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


def upgrade(results: Path, current: Vocabulary) -> list[str]:
    """Bring a results folder written by an older bench up to date, in place (`bench
    upgrade`): the `policy` column of its rows is renamed `method` (`_rename_method`),
    and a recorded vocabulary that lacks this one's fields (`older_fields`) gets the
    package's declarations of its methods and tasks, by name, and of every metric. What it
    changed, one item each (empty: the folder was up to date)."""
    results = Path(results)
    path = results / VOCABULARY
    if not path.is_file():
        raise BenchError(f"{path} not found: not a results folder of `bench run`")
    data = json.loads(path.read_text())
    changed = [c for name in (RUNS, DAMAGED) for c in _rename_method(results / name)]
    older = older_fields(data)
    if older:
        recorded = [*data["methods"], *data["tasks"]]
        unknown = [n for n in recorded if n not in current.methods and n not in current.tasks]
        if unknown:
            raise BenchError(
                f"{path}: {unknown[0]!r} lacks {', '.join(older)} and this bench does not "
                "declare it; run the folder again with a bench that does"
            )
        methods = {n: current.methods[n] for n in data["methods"]}
        tasks = {n: current.tasks[n] for n in data["tasks"]}
        write_text_atomic(path, Vocabulary(methods, tasks, current.metrics).to_json())
        changed.append(f"{VOCABULARY}: declared as this bench does ({', '.join(older)})")
    return changed


def refuse_damage(results: Path) -> None:
    """After an upgrade: damaged rows of the folder's `runs.csv` refused in one line, as
    `bench plot` refuses them (an upgrade recomputes nothing, so it cannot mend them)."""
    if (Path(results) / RUNS).is_file() and check_runs(Path(results) / RUNS)[2]:
        read_runs(Path(results) / RUNS)


def _rename_method(path: Path) -> list[str]:
    """Rename a `runs.csv`'s `policy` column to `method` (`OLD_METHOD`), each row's
    checksum recomputed where it held before (an altered row stays altered)."""
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or OLD_METHOD not in rows[0] or "method" in rows[0]:
        return []
    old = rows[0]
    new = [("method" if c == OLD_METHOD else c) for c in old]
    out = [new]
    for fields in rows[1:]:
        row = dict(zip(old, fields))
        if (
            ROW_CHECKSUM in row
            and len(fields) == len(old)
            and row[ROW_CHECKSUM] == row_checksum(row)
        ):
            row = dict(zip(new, fields))
            row[ROW_CHECKSUM] = row_checksum(row)
            fields = [row[c] for c in new]
        out.append(fields)
    write_text_atomic(path, _csv_lines(out))
    return [f"{path.name}: column {OLD_METHOD} renamed method ({len(rows) - 1} rows)"]
