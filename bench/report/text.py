"""How the results page writes numbers, intervals and tables (Markdown): one way for every
section (`bench.report.page`, `bench.report.nbv`)."""

from __future__ import annotations

import math

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


def ci(mean, lo, hi, note="") -> str:
    """`mean [lo, hi]`, or the mean and why it has no interval (`note`)."""
    if lo is not None and hi is not None and not pd.isna(lo) and not pd.isna(hi):
        return f"{num(mean)} [{num(lo)}, {num(hi)}]"
    return f"{num(mean)}, {note}" if isinstance(note, str) and note else num(mean)


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table's lines."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(r) + " |" for r in rows]
