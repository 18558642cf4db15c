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
    HEADLINE,
    NO_PROTOCOL,
    UNIT_KEY,
    Vocabulary,
    older_fields,
)


def upgrade(results: Path, current: Vocabulary) -> list[str]:
    """Bring a results folder written by an older bench up to date, in place (`bench
    upgrade`): the `policy` column of its rows is renamed `method` (`_rename_method`),
    and a recorded vocabulary that lacks this one's fields (`older_fields`) gets the
    package's declarations of its methods and tasks, by name, and of every metric; the rows
    of a task without tracks are written once (`_rows_once`); a dataset's rows name their
    pixels (`_dataset_pixels`). What it changed, one item
    each (empty: the folder was up to date)."""
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
    untracked = {n for n, t in current.tasks.items() if not t.tracks}
    changed += [c for name in (RUNS, DAMAGED) for c in _rows_once(results / name, untracked)]
    changed += [c for name in (RUNS, DAMAGED) for c in _dataset_pixels(results / name)]
    return changed


def _dataset_pixels(path: Path) -> list[str]:
    """Name the pixels of a dataset's rows written before rows named them: a dataset's
    `render_key` is already the hash of its files' contents (`source_key`), which is its
    `pixels`. A rendered row's pixels cannot be told from its render key (renders differ
    between machines): it stays unnamed, and a run computes it again."""
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or "render_key" not in rows[0]:
        return []
    header = rows[0] if "pixels" in rows[0] else [*rows[0][:-1], "pixels", rows[0][-1]]
    out, named = [header], 0
    for fields in rows[1:]:
        row = dict(zip(rows[0], fields))
        held = ROW_CHECKSUM in row and row[ROW_CHECKSUM] == row_checksum(row)
        if not row.get("pixels") and row["render_key"].startswith("dataset-"):
            row["pixels"] = row["render_key"]
            named += 1
            if held:
                row[ROW_CHECKSUM] = row_checksum(row)
        out.append([row.get(c, "") for c in header])
    if not named:
        return []
    write_text_atomic(path, csv_lines(out))
    return [f"{path.name}: {named} dataset row(s) name their pixels (their contents' hash)"]


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


def _rows_once(path: Path, untracked: set[str]) -> list[str]:
    """Write the rows of the tasks without tracks (`Task.tracks`: pairs) once per unit,
    protocol `NO_PROTOCOL`: an older bench wrote one per track protocol, with the same
    values. The headline protocol's row is kept (else the first), its checksum recomputed
    where it held (an altered row stays altered); the others are dropped."""
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or not {"task", "protocol", *UNIT_KEY} <= set(rows[0]):
        return []
    header = rows[0]

    def old(fields: list[str]) -> bool:
        row = dict(zip(header, fields))
        return (
            len(fields) == len(header)
            and row["task"] in untracked
            and row["protocol"] != NO_PROTOCOL
        )

    if not any(old(f) for f in rows[1:]):
        return []
    units = [tuple(dict(zip(header, f)).get(k) for k in (*UNIT_KEY, "task")) for f in rows[1:]]
    keep = {}
    for n, (fields, unit) in enumerate(zip(rows[1:], units)):
        if old(fields) and (
            unit not in keep or dict(zip(header, fields))["protocol"] == HEADLINE[1]
        ):
            keep[unit] = n
    out = [header]
    for n, (fields, unit) in enumerate(zip(rows[1:], units)):
        if not old(fields):
            out.append(fields)
        elif keep[unit] == n:
            row = dict(zip(header, fields))
            held = ROW_CHECKSUM in row and row[ROW_CHECKSUM] == row_checksum(row)
            row["protocol"] = NO_PROTOCOL
            if held:
                row[ROW_CHECKSUM] = row_checksum(row)
            out.append([row[c] for c in header])
    write_text_atomic(path, csv_lines(out))
    return [
        f"{path.name}: {', '.join(sorted(untracked))} rows written once per unit, protocol "
        f"{NO_PROTOCOL} ({len(keep)} kept, {len(rows) - len(out)} duplicates dropped)"
    ]


def refuse_damage(results: Path) -> None:
    """After an upgrade: damaged rows of the folder's `runs.csv` refused in one line, as
    `bench plot` refuses them (an upgrade recomputes nothing, so it cannot mend them)."""
    if (Path(results) / RUNS).is_file() and check_runs(Path(results) / RUNS)[2]:
        read_runs(Path(results) / RUNS)
