"""`runs.csv`, a results folder's one source of truth: its contract, checked on every read.

Every row is validated: the file's structure (each line has as many fields as the header:
a row cut in the middle is caught), the required columns, the key values (scene, method,
seed >= 0, budget >= 0, a known task and protocol, `none` for a task without tracks;
no key twice), numbers where numbers belong, the status (`ok` rows have their task's headline metrics, `failed` rows a reason).
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
"""

from __future__ import annotations

import csv
import io
import math
import numbers
import os
from pathlib import Path

import pandas as pd

from bench import BenchError
from bench.binding import read_vocabulary
from bench.files import content_key, write_text_atomic
from bench.results import DAMAGED, STALE
from bench.vocabulary import (
    BAG,
    HEADLINE,
    KEY,
    NO_PROTOCOL,
    PROTOCOLS,
    REFERENCE_MAPS,
    REFERENCE_MIN_MAA,
    REFERENCE_PEER,
    Vocabulary,
)

HASHES = ("prediction_hash", "evaluation_hash")
ROW_CHECKSUM = "row_checksum"
"""The last column: a hash of the row's other values as written (`row_checksum`)."""
TEXT_COLUMNS = ("scene", "method", "task", "protocol", "render_key", "pixels", *HASHES, "status")
TEXT_COLUMNS += ("failure", "invocation", "ground_truth", "pairs_rule", BAG, ROW_CHECKSUM)
TEXT_COLUMNS += ("pool", "matcher")
REQUIRED = (*(k for k in KEY if k != BAG), "render_key", *HASHES, "status", "failure")
REQUIRED += ("invocation", "wall_ms")
"""The columns every `runs.csv` has: the key but its `BAG`, which a folder written before
the bag was part of the key lacks (its rows' bag is empty, `_key_of`, `_frame`)."""
OLD_METHOD = "policy"
"""The `method` column's name before 0.3.0 (`bench upgrade` renames it)."""


class DamagedRuns(BenchError):
    """`runs.csv` has damaged rows (`lines`: their line numbers, 1 = the header)."""

    def __init__(self, message: str, lines: list[int]):
        super().__init__(message)
        self.lines = lines


def runs_file(path: Path) -> Path:
    """`path` (a `runs.csv`), or one line saying that there is none."""
    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path} not found: run `bench run` first (or pass --results DIR)")
    return path


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
    if row["protocol"] not in (*PROTOCOLS, NO_PROTOCOL):
        return f"unknown protocol {row['protocol']!r}"
    if (row["protocol"] == NO_PROTOCOL) == vocab.tasks[row["task"]].tracks:
        return f"protocol {row['protocol']!r} in the {row['task']} task" + (
            "" if vocab.tasks[row["task"]].tracks else f" (it has none: {NO_PROTOCOL!r})"
        )
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
    """A row's `KEY` (its bag empty where the file has no `BAG` column)."""
    return tuple(int(row[k]) if k in ("seed", "budget") else row.get(k, "") for k in KEY)


def _key_text(header: list[str], line: str) -> str:
    """` (scene, seed s, method, budget b, task, protocol)` of a row's line, if readable."""
    try:
        row = dict(zip(header, next(csv.reader([line]))))
        return " ({}, seed {}, {}, budget {}, {}, {})".format(*(row[k] for k in REQUIRED[:6]))
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
    check_pixels(df, path)
    df = mark_reference(df, vocab or read_vocabulary(path.parent))
    return df.sort_values(list(KEY), kind="stable", ignore_index=True)


NO_PIXELS = "unrecorded"
"""What `pixels_of` says of a row written before rows named their pixels (before 0.5.0)."""


def pixels_of(rows: pd.DataFrame) -> pd.Series:
    """Each row's `pixels` (the hash of the images its unit read), `NO_PIXELS` for a row
    that names none."""
    if "pixels" not in rows:
        return pd.Series(NO_PIXELS, index=rows.index, dtype=object)
    return rows["pixels"].fillna(NO_PIXELS)


def group_of(rows: pd.DataFrame) -> list[tuple]:
    """Each row's set of views: (scene, seed, bag) (a rendered scene's bag is empty)."""
    bag = rows["bag"].fillna("") if "bag" in rows else pd.Series("", index=rows.index)
    return list(zip(rows["scene"], rows["seed"], bag))


def check_pixels(rows: pd.DataFrame, source: Path | str) -> None:
    """Refuse, in one line naming both hashes and the remedy, rows of one set of views
    (`group_of`) that read different pixels: no pairing, table, tier, transfer or snapshot
    combines them (renders differ in their last bits between machines)."""
    seen: dict[tuple, str] = {}
    for group, px in zip(group_of(rows), pixels_of(rows)):
        if seen.setdefault(group, px) != px:
            scene, seed, bag = group
            where = f"{scene} seed {seed}" + (f" bag {bag}" if bag else "")
            raise BenchError(
                f"{source} mixes rows of {where} read from different pixels ({seen[group]} "
                f"and {px}: other renders, or rows made before rows named their pixels); "
                "recompute them into one folder: `bench run` with the reference renders "
                "(the default) into a new --results folder"
            )


def _frame(header: list[str], good: list[tuple[int, str]]) -> pd.DataFrame:
    text = "\n".join([",".join(header)] + [line for _, line in good])
    return pd.read_csv(
        io.StringIO(text),
        dtype={c: str for c in TEXT_COLUMNS},
        keep_default_na=False,
        na_values=[""],
    ).assign(
        failure=lambda d: d["failure"].fillna(""),
        **{BAG: lambda d: d[BAG].fillna("") if BAG in d else ""},
    )


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


def csv_lines(rows: list[list[str]]) -> str:
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
        text = csv_lines([[t.get(k, "") for k in header] for t in texts])
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
    write_text_atomic(path, csv_lines([header, *body]))


def keep_runs(path: Path, keys: set[tuple]) -> int:
    """Keep the rows of `keys` alone in `runs.csv` (before a run appends the rows it
    computes again): every other row is moved, as it was, to `runs.stale.csv` beside it
    (appended, never deleted; an altered one, which the run scores again, too). How many
    were moved."""
    path = Path(path)
    if not path.is_file():
        return 0
    header, good, bad = check_runs(path)
    keyed = [(_key_of(dict(zip(header, next(csv.reader([line]))))), line) for _, line in good]
    kept = [line for key, line in keyed if key in keys]
    moved = [line for key, line in keyed if key not in keys] + [b[1] for b in bad]
    if not moved:
        return 0
    _append_aside(path.with_name(STALE), header, moved)
    write_text_atomic(path, "\n".join([",".join(header), *kept]) + "\n")
    return len(moved)


def _append_aside(aside: Path, header: list[str], lines: list[str]) -> None:
    """`lines` of a `runs.csv` whose header is `header`, appended to the file `aside` as
    they were (where its header differs, both parts under the union of the two, each row's
    empty fields left out of its checksum as ever)."""
    if aside.exists():
        prior = list(csv.reader(aside.read_text().splitlines()))
        if prior and prior[0] != header:
            rows = [dict(zip(prior[0], f)) for f in prior[1:]]
            rows += [dict(zip(header, f)) for f in csv.reader(lines)]
            union = [k for k in dict.fromkeys([*prior[0], *header]) if k != ROW_CHECKSUM]
            union.append(ROW_CHECKSUM)
            write_text_atomic(
                aside, csv_lines([union, *([r.get(k, "") for k in union] for r in rows)])
            )
            return
    text = aside.read_text() if aside.exists() else ",".join(header) + "\n"
    write_text_atomic(aside, text + "\n".join(lines) + "\n")


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
