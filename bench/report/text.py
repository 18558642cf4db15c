"""How the results page writes numbers, intervals and tables (Markdown): one way for every
section (`bench.report.page`, `bench.report.nbv`); the numbers of a table's column in one
format (`column_format`)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pandas as pd


def num(x) -> str:
    """A number as the page shows it: 3 significant digits, integers whole, n/a if missing."""
    if x is None or (isinstance(x, float) and math.isnan(x)) or x is pd.NA:
        return "n/a"
    x = float(x)
    if math.isnan(x):
        return "n/a"
    if x == int(x) and abs(x) < 1e6:
        return str(int(x))
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:,.0f}"


MAX_DECIMALS = 4
"""The most decimals a page column takes (its CSV has every digit)."""


def _finite(values) -> np.ndarray:
    x = pd.to_numeric(pd.Series(np.ravel(np.asarray(values, dtype=object))), errors="coerce")
    return x[np.isfinite(x)].to_numpy(float)


def column_format(values, *bounds) -> Callable[[object], str]:
    """One format for every number of a table column (`values`, and its intervals'
    `bounds`): integers where every number is whole, else fixed decimals, the fewest from 2
    at which the distinct `values` stay distinct and no number that is not whole reads as a
    whole number (0.9995 is not 1; at most `MAX_DECIMALS`)."""
    x = _finite(values)
    every = np.concatenate([x, *(_finite(b) for b in bounds)])
    if np.all(every == np.round(every)):
        return num
    exact, all_exact = np.unique(np.round(x, 9)), np.unique(np.round(every, 9))
    for d in range(2, MAX_DECIMALS + 1):
        shown = np.round(all_exact, d)
        whole = (shown == np.round(shown)) & (all_exact != np.round(all_exact))
        if len(np.unique(np.round(exact, d))) == len(exact) and not whole.any():
            break
    return lambda v: _fixed(v, d)


def signed(fmt: Callable[[object], str]) -> Callable[[object], str]:
    """`fmt` for a difference: a `+` before a positive number, as a `-` before a negative."""

    def out(v) -> str:
        text = fmt(v)
        return f"+{text}" if text[:1].isdigit() and float(v) > 0 else text

    return out


def _fixed(x, d: int) -> str:
    if x is None or x is pd.NA or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    return f"{float(x):,.{d}f}" if abs(float(x)) >= 1000 else f"{float(x):.{d}f}"


def ci(mean, lo, hi, note="", fmt: Callable[[object], str] = num) -> str:
    """`mean [lo, hi]` (each in `fmt`, a column's format), or the mean and why it has no
    interval (`note`)."""
    if lo is not None and hi is not None and not pd.isna(lo) and not pd.isna(hi):
        return f"{fmt(mean)} [{fmt(lo)}, {fmt(hi)}]"
    return f"{fmt(mean)}, {note}" if isinstance(note, str) and note else fmt(mean)


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table's lines."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(r) + " |" for r in rows]
