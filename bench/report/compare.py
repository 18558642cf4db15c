"""Two sets of rows compared on their common keys, every metric column: what a
reproduction prints (`bench reproduce`, `bench verdict`, `benchmarks/compare_runs.py`).

Three classes: `identical` (every value equal, NaN to NaN); `equal but for last bits`
(values that differ only in the continuous measures bundle adjustment refines,
`LAST_BITS`, within `LAST_BITS_RTOL` of each other: the order of floating-point sums
differs between CPU families, measured up to 1.06e-9 between an Intel and an AMD EPYC
machine); `moved` (any other difference: every score, count and share compares exactly).
"""

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
    "pool",
    "matcher",
}
"""Columns that identify a row or time it: never compared as results (`*_ms` neither)."""
LAST_BITS = (
    "rmse",
    "median_error",
    "mean_reproj_px",
    "median_pose_err_deg",
    "cam_center_err",
    "mean_tri_angle_deg",
)
"""The continuous measures of a reconstruction that bundle adjustment's floating-point
order moves in their last bits between machines (distances, angles, residuals); what a
task ranks by (mAA, AUC, completeness) and every count is never among them."""
LAST_BITS_RTOL = 1e-7
"""Two values of a `LAST_BITS` column within this share of the larger are equal but for
last bits (the largest seen between CPU families: 1.06e-9 on values near 0.1-1)."""


@dataclass
class Comparison:
    """What differs between two sets of rows on their common keys."""

    rows: tuple[int, int]
    common: int
    columns: list[str]
    moved: dict[str, tuple[int, float, str]] = field(default_factory=dict)
    """column -> (values that differ, the largest absolute difference (NaN for text), an
    example 'published -> here')."""
    last_bits: dict[str, tuple[int, float, str]] = field(default_factory=dict)
    """The same, for the `LAST_BITS` columns whose values differ within `LAST_BITS_RTOL`
    alone."""
    pixels: tuple[str, str] | None = None
    """The two sides' pixels where they differ (one value each)."""

    def lines(self) -> list[str]:
        out = [
            f"{self.common} common rows ({self.rows[0]} and {self.rows[1]}), "
            f"{len(self.columns)} metric columns compared"
        ]
        if self.pixels:
            out.append(f"the rows read other pixels: {self.pixels[0]} and {self.pixels[1]}")
        if self.moved:
            total = sum(n for n, _, _ in self.moved.values())
            out.append(f"moved: {total} value(s) in {len(self.moved)} column(s):")
            out += _columns(self.moved)
        if self.last_bits:
            total = sum(n for n, _, _ in self.last_bits.values())
            out.append(
                f"equal but for floating-point last bits: {total} value(s) of "
                f"{', '.join(sorted(self.last_bits))} differ by at most a share of "
                f"{LAST_BITS_RTOL:g} (every other value identical):"
            )
            out += _columns(self.last_bits)
        if not self.moved and not self.last_bits:
            out.append("identical: every metric value of every common row")
        return out


def _columns(found: dict[str, tuple[int, float, str]]) -> list[str]:
    out = []
    for c, (n, diff, example) in sorted(found.items()):
        size = "" if np.isnan(diff) else f", by up to {diff:.3g}"
        out.append(f"  {c}: {n} value(s){size}; e.g. {example}")
    return out


def _plain(values) -> tuple:
    """A row's key, or two values, as plain values (`('facade', 0, ...)`, `0.25`: not
    numpy's scalars)."""
    return tuple(k.item() if isinstance(k, np.generic) else k for k in values)


def compare_rows(a: pd.DataFrame, b: pd.DataFrame) -> Comparison:
    """Every metric column of `a` and `b` (both as `bench.runs.read_runs` gives them) on
    their common keys, in the module docstring's three classes."""
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
            scale = np.maximum(np.abs(xf), np.abs(yf))
            close = same | (np.abs(xf - yf) <= LAST_BITS_RTOL * scale)
        else:
            xs, ys = x.fillna("").astype(str), y.fillna("").astype(str)
            same, diff = (xs == ys).to_numpy(), float("nan")
            close = same
        if not same.all():
            k = int(np.flatnonzero(~same)[0])
            was, now = _plain((x.iloc[k], y.iloc[k]))
            example = f"{_plain(common[k])}: {was!r} -> {now!r}"
            found = out.last_bits if c in LAST_BITS and close.all() else out.moved
            found[c] = (int((~same).sum()), diff, example)
    return out
