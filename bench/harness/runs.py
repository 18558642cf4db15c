"""`runs.csv`, the results folder's one source of truth: its contract, checked on every read.

Every row is validated: the file's structure (each line has as many fields as the header:
a row cut in the middle is caught), the required columns, the key values (scene, policy,
seed >= 0, budget >= 0, a known task and protocol), numbers where numbers belong, the
status (`ok` rows have their task's headline metrics, `failed` rows a reason). A damaged
file is one `BenchError` naming the file and the first bad row, and nothing is published
from it. Recovery: `bench run --set-aside-damaged` moves the damaged rows (as they were)
to `runs.damaged.csv` beside it and computes them again.

A row is finished when its `config_hash` is the current configuration's: the hash covers
the settings and the source of every stage that produces a row's numbers, so rows left
by other code are computed again. A results folder is bound to its settings
(`config.json`); its grid may grow (new scenes, seeds, policies, budgets, tasks run only
the new rows), and only a change of settings needs `--overwrite`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.backend.reconstruction import PROTOCOLS
from bench.files import write_text_atomic
from bench.harness.pipeline import TASKS
from bench.harness.tables import KEY

TEXT_COLUMNS = ("scene", "policy", "task", "protocol", "render_key", "config_hash", "status")
TEXT_COLUMNS += ("failure", "invocation", "ground_truth")
REQUIRED = (*KEY, "render_key", "config_hash", "status", "failure", "invocation", "wall_ms")
OK_NEEDS = {"tri": ("points", "acc_completeness_pct"), "sfm": ("maa", "registered_views")}
"""The metrics an `ok` row of each task must have."""
DAMAGED = "runs.damaged.csv"


class DamagedRuns(BenchError):
    """`runs.csv` has damaged rows (`lines`: their line numbers, 1 = the header)."""

    def __init__(self, message: str, lines: list[int]):
        super().__init__(message)
        self.lines = lines


def _row_problem(row: dict[str, str]) -> str | None:
    """Why one row (raw strings) breaks the contract, or None."""
    for k in ("scene", "policy", "render_key", "config_hash", "invocation"):
        if not row[k]:
            return f"empty {k}"
    for k in ("seed", "budget"):
        try:
            if int(row[k]) < 0 or str(int(row[k])) != row[k]:
                raise ValueError
        except ValueError:
            return f"{k} {row[k]!r} is not a non-negative integer"
    if row["task"] not in TASKS:
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
    needs = OK_NEEDS[row["task"]]
    if row.get("ground_truth") in ("poses", "point cloud"):  # a dataset without pixel truth
        needs = tuple(k for k in needs if k != "acc_completeness_pct")
    for k in needs:
        if k not in row or not row[k] or not math.isfinite(float(row[k])):
            return f"an ok {row['task']} row without {k}"
    return None


def check_runs(path: Path) -> tuple[list[str], list[tuple[int, str]], list[tuple[int, str, str]]]:
    """(header, good rows as (line, text), damaged rows as (line, text, why))."""
    try:
        text = Path(path).read_text()
    except UnicodeDecodeError:
        raise DamagedRuns(f"{path} is damaged: it is not text", [1]) from None
    lines = text.splitlines()
    if not lines:
        raise DamagedRuns(f"{path} is damaged: it is empty", [1])
    header = next(csv.reader([lines[0]]))
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise DamagedRuns(f"{path} is damaged: its header lacks {', '.join(missing)}", [1])
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
        why = _row_problem(dict(zip(header, fields)))
        (bad.append((n, line, why)) if why else good.append((n, line)))
    return header, good, bad


def read_runs(path: Path) -> pd.DataFrame:
    """Every row of a valid `runs.csv`; a damaged one is a `DamagedRuns` error."""
    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path} not found: run `bench run` first (or pass --results DIR)")
    header, good, bad = check_runs(path)
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


def set_aside_damaged(path: Path) -> int:
    """Move the damaged rows of `runs.csv` to `runs.damaged.csv` (appended, as they were);
    how many. A file whose header is damaged is set aside whole."""
    path = Path(path)
    aside = path.with_name(DAMAGED)
    try:
        header, good, bad = check_runs(path)
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


def check_results_dir(results: Path, settings: dict, overwrite: bool) -> None:
    """Refuse to compute into `results` under other row-deciding settings than the ones
    its `config.json` holds, naming each that differs, unless `overwrite`. Writes nothing."""
    settings = json.loads(json.dumps(settings))  # tuples as lists, as stored
    stored_path = results / "config.json"
    if stored_path.exists() and not overwrite:
        try:
            stored = _flatten(json.loads(stored_path.read_text())["settings"])
        except (ValueError, KeyError, TypeError) as e:
            raise BenchError(
                f"{stored_path} is unreadable ({type(e).__name__}); use --overwrite to start again"
            ) from e
        now = _flatten(settings)
        differ = [k for k in sorted(set(stored) | set(now)) if stored.get(k) != now.get(k)]
        if differ:
            shown = "; ".join(
                f"{k}: {stored.get(k)!r} there, {now.get(k)!r} now" for k in differ[:4]
            )
            raise BenchError(
                f"{results} holds results of other settings ({shown}); use --overwrite to "
                "replace them, or another --results folder"
            )


def bind_results_dir(results: Path, settings: dict, overwrite: bool) -> None:
    """Bind `results` to these settings (`config.json`) as the first rows are computed;
    with `overwrite`, the rows and models of other settings go first."""
    if overwrite:
        for name in ("runs.csv", "models", DAMAGED):
            p = results / name
            shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)
    settings = json.loads(json.dumps(settings))
    write_text_atomic(results / "config.json", json.dumps({"settings": settings}, indent=1))
