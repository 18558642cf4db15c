"""Two sets of rows compared on their common keys, every metric column exactly: what a
reproduction prints (`bench reproduce`, `benchmarks/compare_runs.py`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from bench.vocabulary import KEY

NOT_METRICS = {
    "render_key",
    "pixels",
    "prediction_hash",
    "evaluation_hash",
    "invocation",
    "row_checksum",
    "wall_ms",
    "render_s_per_view",
}
"""Columns that identify a row or time it: never compared as results (`*_ms` neither)."""


@dataclass
class Comparison:
    """What differs between two sets of rows on their common keys."""

    rows: tuple[int, int]
    common: int
    columns: list[str]
    moved: dict[str, tuple[int, float, str]] = field(default_factory=dict)
    """column -> (values that differ, the largest absolute difference (NaN for text), an
    example 'published -> here')."""
    pixels: tuple[str, str] | None = None
    """The two sides' pixels where they differ (one value each)."""

    def lines(self) -> list[str]:
        out = [
            f"{self.common} common rows ({self.rows[0]} and {self.rows[1]}), "
            f"{len(self.columns)} metric columns compared exactly"
        ]
        if self.pixels:
            out.append(f"the rows read other pixels: {self.pixels[0]} and {self.pixels[1]}")
        if not self.moved:
            return [*out, "identical: every metric value of every common row"]
        total = sum(n for n, _, _ in self.moved.values())
        out.append(f"{total} value(s) moved in {len(self.moved)} column(s):")
        for c, (n, diff, example) in sorted(self.moved.items()):
            size = "" if np.isnan(diff) else f", by up to {diff:.3g}"
            out.append(f"  {c}: {n} value(s){size}; e.g. {example}")
        return out


def compare_rows(a: pd.DataFrame, b: pd.DataFrame) -> Comparison:
    """Every metric column of `a` and `b` (both as `bench.runs.read_runs` gives them) on
    their common keys; numbers exactly (NaN equal to NaN)."""
    key = [k for k in KEY if k in a and k in b]
    a, b = a.set_index(key).sort_index(), b.set_index(key).sort_index()
    common = a.index.intersection(b.index)
    cols = [
        c for c in a.columns if c in b.columns and c not in NOT_METRICS and not c.endswith("_ms")
    ]
    out = Comparison((len(a), len(b)), len(common), cols)
    if "pixels" in a and "pixels" in b:
        pa, pb = (set(x.loc[common, "pixels"].dropna()) for x in (a, b))
        if pa and pb and pa != pb:
            out.pixels = (", ".join(sorted(pa)), ", ".join(sorted(pb)))
    for c in cols:
        x, y = a.loc[common, c], b.loc[common, c]
        if x.dtype.kind in "fib" and y.dtype.kind in "fib":
            xf, yf = x.astype(float).to_numpy(), y.astype(float).to_numpy()
            same = (xf == yf) | (np.isnan(xf) & np.isnan(yf))
            diff = float(np.nanmax(np.abs(xf - yf)[~same])) if (~same).any() else 0.0
        else:
            xs, ys = x.fillna("").astype(str), y.fillna("").astype(str)
            same, diff = (xs == ys).to_numpy(), float("nan")
        if not same.all():
            k = int(np.flatnonzero(~same)[0])
            example = f"{common[k]}: {x.iloc[k]!r} -> {y.iloc[k]!r}"
            out.moved[c] = (int((~same).sum()), diff, example)
    return out
