"""`bench upgrade`: a results folder written by an older bench brought up to date, in place."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from bench import BenchError
from bench.files import write_text_atomic
from bench.results import DAMAGED, RUNS, VOCABULARY
from bench.runs import OLD_METHOD, ROW_CHECKSUM, check_runs, csv_lines, read_runs, row_checksum
from bench.vocabulary import (
    Vocabulary,
    older_fields,
)


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
    write_text_atomic(path, csv_lines(out))
    return [f"{path.name}: column {OLD_METHOD} renamed method ({len(rows) - 1} rows)"]


def refuse_damage(results: Path) -> None:
    """After an upgrade: damaged rows of the folder's `runs.csv` refused in one line, as
    `bench plot` refuses them (an upgrade recomputes nothing, so it cannot mend them)."""
    if (Path(results) / RUNS).is_file() and check_runs(Path(results) / RUNS)[2]:
        read_runs(Path(results) / RUNS)
