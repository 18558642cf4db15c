"""What a run's rows say went wrong, in a line: the rows that failed (by reason), the rows
that could not be computed (a method raised or broke its contract, a worker died), and the
(scene, seed) cells left out of the means of the tasks with the exclusion rule (sfm). For `bench run`'s summary and Figure 3."""

from __future__ import annotations

import re

import pandas as pd

from bench.vocabulary import REFERENCE_MAPS, REFERENCE_PEER, Vocabulary

ERROR = "error: "
"""How the failure of a row that could not be computed starts (`bench.harness.execute`);
a task's outcome (a mapper that registered no view) does not start so."""


NUMBER = re.compile(r"\d+")
HOLE = "\x00"
"""Where a number of a failure was, in the reason its rows are grouped by."""


def _kind(row) -> str:
    """A failure's reason with `HOLE` for each number (an error: its method)."""
    if row.failure.startswith(ERROR):
        return f"{row.task}: error of {row.method}"
    return f"{row.task}: {NUMBER.sub(HOLE, row.failure)[:60]}"


def _values(numbers: list[int]) -> str:
    """The numbers a hole of a reason stood for: '0', '0 or 1', '0 to 3'."""
    lo, hi = min(numbers), max(numbers)
    return str(lo) if lo == hi else f"{lo} or {hi}" if len(set(numbers)) == 2 else f"{lo} to {hi}"


def _said(kind: str, failed: list[str]) -> str:
    """A reason with each hole filled by the numbers it stood for in its rows' failures."""
    holes = kind.count(HOLE)
    found = [[int(x) for x in NUMBER.findall(f)][:holes] for f in failed]
    for i in range(holes):
        kind = kind.replace(HOLE, _values([f[i] for f in found]), 1)
    return kind


def failures(rows: pd.DataFrame) -> str:
    """'N failed (n task: reason; ...)', each number of a reason as its rows had it (0,
    0 or 1, 0 to 3), or '' when no row failed."""
    failed = rows[rows["status"] == "failed"]
    if failed.empty:
        return ""
    kinds: dict[str, list[str]] = {}
    for r in failed.itertuples():
        kinds.setdefault(_kind(r), []).append(r.failure)
    by_count = sorted(kinds.items(), key=lambda kv: -len(kv[1]))
    said = [f"{len(fs)} {_said(k, fs)}" for k, fs in by_count]
    return f"{len(failed)} failed ({'; '.join(said)})"


def outcomes(rows: pd.DataFrame) -> str:
    """Why failed rows that are a task's outcome (not an error) are not a fault, or ''."""
    failed = rows[rows["status"] == "failed"]["failure"].fillna("")
    if not (~failed.str.startswith(ERROR)).any():
        return ""
    photos = "bag" in rows and rows["bag"].notna().any()  # a dataset's rows: no render
    small = "small budgets" + ("" if photos else " and renders (--quick)")
    return (
        "a failed row is a task's outcome (a map or track not made), scored at each metric's "
        f"failure value (mAA 0), not an error: expected more often at {small}"
    )


def errors(rows: pd.DataFrame) -> str:
    """'N row(s) of METHOD[, ...] could not be computed: FIRST FAILURE', or ''."""
    bad = rows[rows["failure"].fillna("").str.startswith(ERROR)]
    if bad.empty:
        return ""
    methods = ", ".join(f"{p} ({n})" for p, n in bad["method"].value_counts().items())
    first = bad["failure"].iloc[0][len(ERROR) :]
    return f"{len(bad)} row(s) could not be computed, of {methods}; the first: {first}"


def exclusion_rule(df: pd.DataFrame, vocab: Vocabulary, dataset: bool = False) -> str:
    """Whether the exclusion rule of the tasks with it (`Task.exclusion_reference`: sfm)
    is applied to the rows `df` ("applied") or why not: on a dataset (its poses are the
    truth), or where stock COLMAP with all features did not run in every (scene, seed)
    cell of those tasks (the rule is all or nothing, so that a mean never depends on which
    cells it ran in)."""
    if dataset:
        return "not applied: a dataset's poses are the truth"
    cells = df[df["task"].isin(vocab.exclusion_tasks)].drop_duplicates(["scene", "seed"])
    known = cells[REFERENCE_MAPS].notna().sum() if REFERENCE_MAPS in cells else 0
    if known < len(cells):
        return f"not applied: {REFERENCE_PEER} did not run in {len(cells) - known} of {len(cells)} cells"
    return "applied"


def exclusions(rows: pd.DataFrame, vocab: Vocabulary, dataset: bool = False) -> str:
    """Which (scene, seed) cells the means of the tasks with the exclusion rule leave out
    and why, why none is left out where the rule does not apply, or '' without such a
    task."""
    ruled = [t for t in vocab.exclusion_tasks if (rows["task"] == t).any()]
    if not ruled:
        return ""
    rule, names = exclusion_rule(rows, vocab, dataset), "/".join(ruled)
    if rule != "applied":
        return f"{names} exclusion rule {rule}"
    cells = rows[rows[REFERENCE_MAPS].eq(0)][["scene", "seed"]].drop_duplicates()
    if cells.empty:
        return ""
    which = ", ".join(f"{s} seed {d}" for s, d in sorted(map(tuple, cells.to_numpy())))
    total = len(rows[["scene", "seed"]].drop_duplicates())
    return (
        f"{names} means leave out {len(cells)} of {total} (scene, seed): {which} "
        f"({REFERENCE_PEER} with all features does not map them)"
    )
