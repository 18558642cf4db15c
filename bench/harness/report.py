"""Tables and figures from `runs.csv` alone (Figure 2 also reads the exported model and the
cached render). Nothing here renders or reconstructs.

Aggregates: the mean over runs with a 95% confidence half-width t(0.975, n-1) * s / sqrt(n).
A run that reconstructed nothing has no rmse (NaN, left out of the rmse mean; the table
counts such runs) and zero completeness (kept in the completeness mean).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

from bench import BenchError  # noqa: E402
from bench.console import log  # noqa: E402
from bench.files import write_text_atomic  # noqa: E402

KEY = ("scene", "seed", "policy", "budget")
DISPLAY = {
    "random": "Random budget",
    "texture": "Texture-only",
    "grid": "Uniform grid",
    "adaptive": "Adaptive optimized",
    "all": "All candidates (reference)",
}
BASELINES = ("random", "texture", "grid")
HEADLINE = (
    "rmse",
    "acc_completeness_pct",
    "inlier_pct",
    "coverage_pct",
    "runtime_proxy",
    "wall_ms",
)
"""The paper's Table 1 columns (plus measured wall-clock)."""
TABLE1_METRICS = (
    *HEADLINE,
    "median_error",
    "match_precision_pct",
    "acc_completeness_pct_0.02",
    "acc_completeness_pct_0.05",
    "acc_completeness_pct_0.20",
    "points",
    "mean_track_length",
    "mean_tri_angle_deg",
    "runtime_scoring",
    "runtime_matching",
    "runtime_robust",
)
FIGURE3_METRICS = (
    ("rmse", "RMSE (scene units)"),
    ("acc_completeness_pct", "Acc. completeness % (e < 0.10)"),
    ("inlier_pct", "Inlier %"),
    ("coverage_pct", "Coverage %"),
    ("runtime_proxy", "Runtime proxy (k ops)"),
    ("match_precision_pct", "Match precision %"),
)
REQUIRED = (*KEY, *HEADLINE, "render_key")


def load_runs(path: Path) -> pd.DataFrame:
    """Read and check `runs.csv`; a missing or malformed file is a one-line `BenchError`."""
    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path} not found: run `bench run` first (or pass --results DIR)")
    try:
        df = pd.read_csv(path)
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise BenchError(f"{path} is malformed: {str(e).splitlines()[0]}") from e
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise BenchError(f"{path} is malformed: missing columns {', '.join(missing)}")
    if df.empty:
        raise BenchError(f"{path} holds no runs")
    for c in REQUIRED[4:-1]:
        if not pd.api.types.is_numeric_dtype(df[c]):
            raise BenchError(f"{path} is malformed: column {c} is not numeric")
    return df


def mean_ci(x: pd.Series) -> tuple[float, float]:
    """Mean of the finite values and the 95% confidence half-width (NaN for n < 2)."""
    x = x[np.isfinite(x)]
    n = len(x)
    if n == 0:
        return math.nan, math.nan
    half = stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n) if n > 1 else math.nan
    return float(x.mean()), float(half)


def table1(df: pd.DataFrame) -> pd.DataFrame:
    """Per strategy (and budget): every metric's mean and 95% CI over runs."""
    out = []
    for (policy, budget), g in df.groupby(["policy", "budget"], sort=False):
        row = {
            "strategy": DISPLAY.get(policy, policy),
            "policy": policy,
            "budget": budget,
            "runs": len(g),
        }
        row["failed_runs"] = int((g.get("status", pd.Series("ok", index=g.index)) != "ok").sum())
        for m in TABLE1_METRICS:
            if m in g:
                row[m], row[f"{m}_ci95"] = mean_ci(g[m].astype(float))
        out.append(row)
    order = {p: i for i, p in enumerate(DISPLAY)}
    return (
        pd.DataFrame(out)
        .sort_values(["budget", "policy"], key=lambda s: s.map(order) if s.name == "policy" else s)
        .reset_index(drop=True)
    )


def table2(df: pd.DataFrame) -> pd.DataFrame:
    """Per scene (and budget): adaptive against the best of random, texture and grid."""
    out = []
    for (scene, budget), g in df.groupby(["scene", "budget"], sort=False):
        means = g.groupby("policy")[["rmse", "acc_completeness_pct"]].mean()
        base = means.loc[[p for p in BASELINES if p in means.index]]
        row = {"scene": scene, "budget": budget}
        row["adaptive_rmse"] = means["rmse"].get("adaptive", math.nan)
        finite = base["rmse"].dropna()
        row["best_baseline_rmse"] = finite.min() if len(finite) else math.nan
        row["best_baseline_rmse_policy"] = finite.idxmin() if len(finite) else ""
        row["adaptive_acc_completeness_pct"] = means["acc_completeness_pct"].get(
            "adaptive", math.nan
        )
        comp = base["acc_completeness_pct"].dropna()
        row["best_baseline_acc_completeness_pct"] = comp.max() if len(comp) else math.nan
        row["best_baseline_acc_completeness_policy"] = comp.idxmax() if len(comp) else ""
        out.append(row)
    return pd.DataFrame(out)


def figure3(t1: pd.DataFrame, out: Path) -> None:
    """Aggregate metrics per strategy with 95% CI error bars (the main budget)."""
    t = t1[t1["budget"] == t1["budget"].max()]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    colors = plt.cm.tab10(np.arange(len(t)))
    for ax, (m, label) in zip(axes.ravel(), FIGURE3_METRICS):
        ax.bar(range(len(t)), t[m], yerr=np.nan_to_num(t[f"{m}_ci95"]), color=colors, capsize=4)
        ax.set_xticks(
            range(len(t)),
            [s.replace(" (reference)", "\n(reference)") for s in t["strategy"]],
            rotation=30,
            ha="right",
            fontsize=8,
        )
        ax.set_title(label, fontsize=10)
        if m == "runtime_proxy":
            ax.set_yscale("log")  # the `all` reference is orders of magnitude above
    fig.suptitle(
        f"Aggregate metrics per strategy (budget {int(t['budget'].iloc[0])}; mean and 95% CI over runs)"
    )
    fig.tight_layout()
    _save(fig, out, ("png", "pdf"))


def figure_budget(t1: pd.DataFrame, out: Path) -> None:
    """Each metric against the budget, one line per strategy."""
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for ax, (m, label) in zip(axes.ravel(), FIGURE3_METRICS):
        for policy, g in t1[t1["policy"] != "all"].groupby("policy", sort=False):
            ax.errorbar(
                g["budget"],
                g[m],
                yerr=np.nan_to_num(g[f"{m}_ci95"]),
                marker="o",
                capsize=3,
                label=DISPLAY.get(policy, policy),
            )
        ax.set_xscale("log", base=2)
        ax.set_xlabel("budget per view")
        ax.set_title(label, fontsize=10)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    _save(fig, out, ("png",))


def _save(fig, out: Path, formats) -> None:
    for fmt in formats:
        path = out.with_suffix(f".{fmt}")
        tmp = path.with_name(f".{path.stem}.tmp.{fmt}")
        fig.savefig(tmp, dpi=130)
        tmp.replace(path)
    plt.close(fig)


def figure2(df: pd.DataFrame, results: Path, renders: Path, out: Path) -> str | None:
    """Two views of `table` with the adaptive selection, and its sparse points coloured by
    error. Returns why it could not be drawn, or None."""
    import cv2
    import pycolmap
    from scipy.spatial import cKDTree

    from bench.evaluation.groundtruth import load_ground_truth

    rows = df[(df["scene"] == "table") & (df["policy"] == "adaptive")].sort_values(
        ["seed", "budget"]
    )
    if rows.empty:
        return "no adaptive run of the table scene in runs.csv"
    r = rows.iloc[0]
    model_dir = results / "models" / f"table-s{r['seed']}" / f"adaptive-b{r['budget']}"
    entry = renders / r["render_key"]
    if not model_dir.is_dir() or not entry.is_dir():
        return f"missing {model_dir if not model_dir.is_dir() else entry}"
    model = pycolmap.Reconstruction(str(model_dir))
    gts = load_ground_truth(entry)
    surface = cKDTree(np.concatenate([g.position[g.single_surface] for g in gts]))
    X = np.array([p.xyz for p in model.points3D.values()]).reshape(-1, 3)
    err = surface.query(X)[0] if len(X) else np.zeros(0)
    fig = plt.figure(figsize=(15, 4.8))
    for k, image_id in enumerate(sorted(model.images)[:: max(1, len(model.images) - 1)][:2]):
        img = model.images[image_id]
        ax = fig.add_subplot(1, 3, k + 1)
        ax.imshow(cv2.imread(str(entry / img.name))[..., ::-1])
        xy = (
            np.array([p.xy for p in img.points2D]).reshape(-1, 2) - 0.5
        )  # COLMAP -> matplotlib pixel centres
        tri = np.array([p.has_point3D() for p in img.points2D], bool)
        ax.scatter(
            *xy[~tri].T,
            s=6,
            facecolors="none",
            edgecolors="yellow",
            linewidths=0.6,
            label="selected",
        )
        ax.scatter(*xy[tri].T, s=8, c="red", label="selected and triangulated")
        ax.set_title(f"{img.name}: {len(xy)} adaptive features", fontsize=10)
        ax.axis("off")
        if k == 0:
            ax.legend(loc="lower left", fontsize=8)
    ax = fig.add_subplot(1, 3, 3, projection="3d")
    if len(X):
        keep = np.linalg.norm(X - np.median(X, 0), axis=1) < 4 * np.percentile(
            np.linalg.norm(X - np.median(X, 0), axis=1), 75
        )
        sc = ax.scatter(
            *X[keep].T, c=np.minimum(err[keep], 0.2), cmap="viridis", s=4, vmin=0, vmax=0.2
        )
        fig.colorbar(sc, ax=ax, shrink=0.6, label="point error (scene units, clipped at 0.2)")
        ax.view_init(elev=25, azim=-100)
    ax.set_title(
        f"{len(X)} sparse points (table, seed {r['seed']}, budget {r['budget']})", fontsize=10
    )
    fig.tight_layout()
    _save(fig, out, ("png",))
    return None


def write_report(df: pd.DataFrame, results: Path, renders: Path) -> None:
    """table1.csv, table2.csv, figure3.png/.pdf, the budget figure, figure2.png."""
    results = Path(results)
    t1, t2 = table1(df), table2(df)
    for name, t in (("table1.csv", t1), ("table2.csv", t2)):
        write_text_atomic(results / name, t.to_csv(index=False, float_format="%.6g"))
    figure3(t1, results / "figure3")
    if df["budget"].nunique() > 1:
        figure_budget(t1, results / "figure_budget")
    why = figure2(df, results, Path(renders), results / "figure2")
    if why:
        log(f"figure2.png not drawn: {why}")
