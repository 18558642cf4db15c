"""Figures from the tables (Figure 2 also reads the exported model and the cached render).

Intervals are the tables' (`bench.report.stats`); a value that is missing (no run, or
no interval: a scene with one seed) is drawn as missing ("n/a", no error bar), never as a
zero-height bar.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import FixedLocator, MaxNLocator, NullLocator  # noqa: E402
from matplotlib.transforms import Bbox  # noqa: E402

from bench.files import META, atomic_path  # noqa: E402
from bench.results import POINT_ERRORS, Workspace
from bench.vocabulary import (  # noqa: E402
    FIGURE_SCENE,
    GROUND_TRUTH,
    HEADLINE,
    HEADLINE_BUDGET,
    HEADLINE_POLICY,
    PER_VIEW,
    Job,
    Unit,
    Vocabulary,
)

LOG_SCALE = {"runtime_proxy", "rmse"}
CATEGORY_MAPS = {"image": "Blues", "views": "Oranges", "truth": "Greens"}
"""Each category of what a selection sees has its colour family (others: greys)."""
CATEGORY_NAMES = {"image": "sees its image", "views": "sees other views", "truth": "sees the truth"}
"""Figure 3's name of each category (others: "other methods")."""
SEES_ORDER = {"image": 0, "views": 1, "truth": 2}
PEERS = ("peer",)
"""The roles whose whole-pool rows (budget 0) stand in Figure 3: stock COLMAP's default
(not `all`, the whole pool, which no budget holds)."""


def method_colours(methods, vocab: Vocabulary) -> dict:
    """One colour per method, unique: its category's colour family (`CATEGORY_MAPS`), a
    shade of its own within it."""
    by_sees: dict[str, list[str]] = {}
    for m in dict.fromkeys(methods):
        by_sees.setdefault(vocab.sees(m) if m in vocab.methods else "", []).append(m)
    out = {}
    for sees, ms in by_sees.items():
        cmap = plt.get_cmap(CATEGORY_MAPS.get(sees, "Greys"))
        shades = np.linspace(0.9, 0.35, len(ms)) if len(ms) > 1 else [0.7]
        out |= {m: cmap(x) for m, x in zip(ms, shades)}
    return out


MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*", "<", ">", "h", "p", "d", "8")
DASHES = (":", "--", "-.", (0, (1, 3)), (0, (5, 2, 1, 2)), (0, (3, 1, 1, 1, 1, 1)))


def method_styles(methods, vocab: Vocabulary) -> dict[str, dict]:
    """Per method, a colour (`method_colours`), a marker and a line style, each pair of
    marker and line style its own within its category: a method's mark is found without
    telling shades apart."""
    colours = method_colours(methods, vocab)
    seen: dict[str, int] = {}
    out = {}
    for m in dict.fromkeys(methods):
        k = seen[sees] = seen.get(sees := vocab.sees(m) if m in vocab.methods else "", -1) + 1
        marker, dash = MARKERS[k % len(MARKERS)], DASHES[(k // len(MARKERS)) % len(DASHES)]
        out[m] = {"color": colours[m], "marker": marker, "linestyle": dash}
    return out


def headline_budget(t1: pd.DataFrame) -> int:
    """256 when the table has it, else its middle budget (0 when it has whole-pool methods
    only)."""
    budgets = sorted(b for b in t1["budget"].unique() if b > 0)
    if not budgets:
        return 0
    return HEADLINE_BUDGET if HEADLINE_BUDGET in budgets else budgets[len(budgets) // 2]


def runs_said(t: pd.DataFrame, metrics: list[str], vocab: Vocabulary) -> str:
    """How Figure 3's means were taken, in Table 1's terms: the runs each counts (`runs`,
    less those a task's exclusion rule leaves out) and their interval, or why there is
    none (`note`: an interval needs two seeds in every scene, a run per seed)."""
    counts = set()
    for m in metrics:
        excluded = t.get(vocab.column(vocab.split(m)[0], "excluded_runs"), 0)
        counts |= set((t["runs"] - excluded).fillna(t["runs"])[t[m].notna()].astype(int))
    if not counts:
        return "no method has a value"
    runs = "-".join(map(str, sorted({min(counts), max(counts)}))) + " run" + "s" * (max(counts) > 1)
    if any(t[f"{m}_lo"].notna().any() for m in metrics):
        return f"mean and 95% interval over {runs} per method"
    parts = [p.rpartition(": ") for note in t["note"].dropna() for p in note.split("; ")]
    why = {w for w, _, ms in parts if set(ms.split(", ")) & set(metrics)}
    why = {re.sub(r"n/a \((\d+ seeds?)\)", r"a scene with \1", w) for w in why}
    return f"mean of {runs} per method, no interval: " + "; ".join(sorted(why))


def figure3(
    t1: pd.DataFrame, vocab: Vocabulary, out: Path, title: str = "", note: str = ""
) -> None:
    """Per method at the headline budget (references and peers included), each task's
    first headline metric with its 95% interval: one panel per task that has a value, the
    metric Table 1 tiers and the verdicts judge (the others, and other budgets, are Table
    1's and `figure_budget`'s). Methods are rows, named once, under their category of
    `sees` (named in each panel), each with its marker and interval line (`method_styles`);
    `note` (what failed, what the means leave out) below the panels."""
    b = headline_budget(t1)
    whole = t1["method"].map(lambda m: m in vocab.methods and vocab.methods[m].role not in PEERS)
    t = t1[(t1["budget"] == b) | ((t1["budget"] == 0) & ~whole)].reset_index(drop=True)
    t = t.assign(_sees=t["method"].map(lambda m: vocab.sees(m) if m in vocab.methods else ""))
    order = t["_sees"].map(SEES_ORDER).fillna(len(SEES_ORDER))
    t = t.loc[order.sort_values(kind="stable").index].reset_index(drop=True)
    every = [m for m in vocab.first_headline() if m in t] or [
        m for m, _ in vocab.panels() if m in t
    ]  # a grid without any task's first headline metric: its drawn ones
    panels = [m for m in every if np.isfinite(t[m].astype(float)).any()] or every[:1]
    heads = t["_sees"].ne(t["_sees"].shift()).to_numpy()
    y = np.arange(len(t)) + heads.cumsum()  # a row above each category for its name
    width = max(8.0, 2 + 4 * len(panels))
    fig, axes = plt.subplots(
        1, len(panels), figsize=(width, 2.2 + 0.2 * y[-1]), sharey=True, squeeze=False
    )
    styles = method_styles(t["method"], vocab)
    titles = dict(vocab.panels())
    for ax, m in zip(axes[0], panels):
        values, lo, hi = (t[c].to_numpy(float) for c in (m, f"{m}_lo", f"{m}_hi"))
        for k, method in enumerate(t["method"]):
            if not np.isfinite(values[k]):
                ax.text(
                    0.02,
                    y[k],
                    "n/a",
                    transform=ax.get_yaxis_transform(),
                    va="center",
                    fontsize=8,
                    color="gray",
                )
                continue
            style = styles[method]
            xerr = [[values[k] - lo[k]], [hi[k] - values[k]]] if np.isfinite(lo[k]) else None
            line = ax.errorbar(
                values[k], y[k], xerr=xerr, fmt=style["marker"], color=style["color"], capsize=3
            )
            for bar in line[2]:
                bar.set_linestyle(style["linestyle"])
        for k in np.flatnonzero(heads):
            sees = t["_sees"][k]
            ax.text(
                0.01,
                y[k] - 1,
                CATEGORY_NAMES.get(sees, "other methods"),
                fontsize=8,
                transform=ax.get_yaxis_transform(),
                va="center",
                style="italic",
                color=plt.get_cmap(CATEGORY_MAPS.get(sees, "Greys"))(0.8),
            )
        ax.grid(axis="x", alpha=0.3)
        ax.set_title(titles.get(m, m), fontsize=10)
        if m in LOG_SCALE and (values[np.isfinite(values)] > 0).any():
            ax.set_xscale("log")
    axes[0, 0].set_yticks(y, t["method"], fontsize=8)
    axes[0, 0].set_ylim(y[-1] + 0.8, -0.8)  # the first row on top
    fig.suptitle(
        title
        or f"Each task's headline metric per method at budget {b}\n"
        f"{runs_said(t, panels, vocab)}; colour: what its selection sees, marker: the method",
        fontsize=11,
    )
    bottom = 0.0
    if note:
        fig.text(0.01, 0.005, note, fontsize=8, wrap=True, va="bottom")
        bottom = min(0.25, (0.1 + 0.18 * (1 + note.count("\n"))) / fig.get_figheight())
    fig.tight_layout(rect=(0, bottom, 1, 1))  # the overall title's band its own
    save(fig, out, ("png", "pdf"))


def _line_style(k: int) -> dict:
    """The k-th policy's line in the budget figure: nine distinct hues (tab10 without its
    grey, the references' colour), then the same hues with another marker and dash, so no
    two lines look alike."""
    hues = [plt.cm.tab10(i) for i in (0, 1, 2, 3, 4, 5, 6, 8, 9)]
    return {
        "color": hues[k % 9],
        "marker": "os^Dv"[(k // 9) % 5],
        "linestyle": ("-", "--", "-.", (0, (1, 1)), (0, (5, 1, 1, 1)))[(k // 9) % 5],
    }


def figure_budget(t1: pd.DataFrame, vocab: Vocabulary, out: Path) -> None:
    """Each metric the tasks draw (`Vocabulary.panels`) against the budget per policy
    (oracle included), with 95% interval bands; the `all` reference as a dashed line."""
    panels = vocab.panels()
    rows = max(3, -(-len(panels) // 3))
    fig, axes = plt.subplots(rows, 3, figsize=(15, 11 / 3 * rows))
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    budgets = sorted(b for b in t1["budget"].unique() if b > 0)
    for ax, (m, label) in zip(axes.ravel(), panels):
        if m not in t1:
            ax.set_visible(False)
            continue
        truth = vocab.with_kind(GROUND_TRUTH)
        curves = [p for p in t1.loc[t1["budget"] > 0, "method"].unique() if p not in truth]
        for policy, g in t1[t1["budget"] > 0].groupby("method", sort=False):
            g = g.sort_values("budget")
            style = (
                {"linestyle": ":", "color": "black", "marker": "o"}
                if policy in truth
                else _line_style(curves.index(policy))
            )
            line = ax.plot(g["budget"], g[m], label=g["strategy"].iloc[0], **style)
            ax.fill_between(
                g["budget"], g[f"{m}_lo"], g[f"{m}_hi"], color=line[0].get_color(), alpha=0.15
            )
        for policy, ref in t1[t1["budget"] == 0].groupby("method", sort=False):
            if np.isfinite(ref[m].iloc[0]):
                style = "--" if policy in vocab.with_kind(PER_VIEW) else "-."
                ax.axhline(
                    ref[m].iloc[0], color="gray", linestyle=style, label=ref["strategy"].iloc[0]
                )
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(FixedLocator(budgets))
        ax.xaxis.set_minor_locator(NullLocator())
        ax.set_xticklabels([str(b) for b in budgets])
        ax.set_xlabel("budget per view")
        ax.set_title(label, fontsize=10)
        if not np.isfinite(t1.loc[t1["budget"] > 0, m].to_numpy(float)).any():
            ax.set_yticks([])
            ax.text(0.5, 0.5, "n/a: no run has this value", transform=ax.transAxes, ha="center")
        elif m in LOG_SCALE and (t1[m] > 0).any():
            ax.set_yscale("log")
    entries = {}  # every panel's lines, once each (a reference may have one metric only)
    for ax in axes.ravel():
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    fig.legend(
        entries.values(), entries.keys(), loc="lower center", ncol=3, fontsize=8, frameon=False
    )
    fig.suptitle("Headline metrics against the budget (mean and 95% interval band over runs)")
    legend_in = 0.17 * -(-len(entries) // 3) + 0.2  # three long names a line, inside the width
    bottom = legend_in / fig.get_figheight()
    fig.tight_layout(rect=(0, bottom, 1, 0.97))  # the legend below the panels, over no curve
    save(fig, out, ("png",))


def save(fig, out: Path, formats) -> None:
    for fmt in formats:
        with atomic_path(out.with_suffix(f".{fmt}")) as tmp:
            fig.savefig(tmp, dpi=120)
    plt.close(fig)


def read_text_model(folder: Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """An exported COLMAP text model, read without COLMAP: {image name: (keypoints (N, 2)
    in COLMAP's pixel convention, whether each observes a point)}, the point ids and
    their positions (M, 3)."""
    lines = [x for x in (folder / "images.txt").read_text().splitlines() if not x.startswith("#")]
    images = {}
    for head, obs in zip(lines[::2], lines[1::2]):
        values = np.array(obs.split(), float).reshape(-1, 3)
        images[head.split()[9]] = (values[:, :2], values[:, 2] >= 0)
    rows = [
        x.split()[:4]
        for x in (folder / "points3D.txt").read_text().splitlines()
        if x and not x.startswith("#")
    ]
    table = np.array(rows, float).reshape(-1, 4)
    return images, table[:, 0].astype(int), table[:, 1:]


def figure2_expected(df: pd.DataFrame) -> bool:
    """Whether the rows ask for Figure 2 (they hold the headline method on the figure's
    scene), so that not drawing it is worth saying."""
    return bool(((df["scene"] == FIGURE_SCENE) & (df["method"] == HEADLINE_POLICY)).any())


def entry_of(renders: Path, key: str, pixels) -> Path:
    """The cached render entry a row read: its `render_key`'s, among a local render and an
    entry made from the reference renders (`renders/reference/`), the one of its `pixels`."""
    found = [e for e in (Path(renders) / key, Path(renders) / "reference" / key) if e.is_dir()]
    same = [e for e in found if _recorded_pixels(e) == pixels]
    return (same or found or [Path(renders) / key])[0]


def _recorded_pixels(entry: Path) -> str | None:
    try:
        return json.loads((entry / META).read_text()).get("pixels")
    except (OSError, ValueError):
        return None


def figure2(df: pd.DataFrame, results: Path, renders: Path, out: Path) -> str | None:
    """Two views of the figure's scene (`FIGURE_SCENE`) with the headline method's
    selection, and its sparse points coloured by their error (`POINT_ERRORS`, written by
    the evaluation). Returns why it could not be drawn, or None."""
    rows = df[
        (df["scene"] == FIGURE_SCENE)
        & (df["method"] == HEADLINE_POLICY)
        & (df["task"] == HEADLINE[0])
        & (df["protocol"] == HEADLINE[1])
    ]
    if rows.empty:
        return (
            f"it shows the points of the {HEADLINE[0]} task of {HEADLINE_POLICY} on "
            f"{FIGURE_SCENE} under the {HEADLINE[1]} protocol, and runs.csv holds none"
        )
    rows = rows.assign(off=(rows["budget"] - HEADLINE_BUDGET).abs()).sort_values(["off", "seed"])
    r = rows.iloc[0]
    unit = Unit(FIGURE_SCENE, int(r["seed"]), HEADLINE_POLICY, int(r["budget"]))
    model_dir = Workspace(results, renders).model_dir(unit, Job(*HEADLINE))
    entry = entry_of(renders, r["render_key"], r.get("pixels"))
    if not (model_dir / "images.txt").is_file() or not entry.is_dir():
        return f"missing {model_dir if not model_dir.is_dir() else entry}"
    images, ids, X = read_text_model(model_dir)
    errors = model_dir / POINT_ERRORS
    err = np.zeros(len(ids))
    if errors.is_file() and len(ids):
        known = pd.read_csv(errors).set_index("point3D_id")["error"]
        err = known.reindex(ids).to_numpy(float)
    fig = plt.figure(figsize=(15, 4.8))
    names = sorted(images)
    for k, name in enumerate(names[:: max(1, len(names) - 1)][:2]):
        xy, tri = images[name]
        xy = xy - 0.5  # COLMAP -> matplotlib pixel centres
        ax = fig.add_subplot(1, 3, k + 1)
        ax.imshow(plt.imread(entry / name))
        ax.scatter(
            *xy[~tri].T,
            s=6,
            facecolors="none",
            edgecolors="yellow",
            linewidths=0.6,
            label="selected",
        )
        ax.scatter(*xy[tri].T, s=8, c="red", label="selected and triangulated")
        ax.set_title(f"{name}: {len(xy)} {HEADLINE_POLICY} features", fontsize=10)
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
        f"{len(X)} sparse points ({FIGURE_SCENE}, seed {r['seed']}, budget {r['budget']})",
        fontsize=10,
    )
    fig.tight_layout()
    save(fig, out, ("png",))
    return None


def figure_transfer(ranks: pd.DataFrame, summary: pd.DataFrame, budget: int, out: Path) -> None:
    """Rendered rank against dataset rank at one budget, a panel per dataset, category of
    `sees` and metric, each point named (`label_points`)."""
    panels = summary[summary["budget"] == budget]
    cols = min(4, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.6 * cols, 4.6 * rows), squeeze=False, constrained_layout=True
    )
    for ax in axes.ravel()[len(panels) :]:
        fig.delaxes(ax)
    drawn = []
    for ax, (_, s) in zip(axes.ravel(), panels.iterrows()):
        r = ranks[
            (ranks["dataset"] == s["dataset"])
            & (ranks["sees"] == s["sees"])
            & (ranks["metric"] == s["metric"])
            & (ranks["budget"] == budget)
        ]
        n = len(r)
        ax.plot([1, n], [1, n], color="0.8", lw=1)
        ax.scatter(r["rank_rendered"], r["rank_dataset"], s=18)
        drawn.append((ax, r))
        ax.set(
            xlabel="rank on the rendered benchmark",
            ylabel=f"rank on {s['dataset']}",
            title=f"{s['metric']}, sees {s['sees']}, B = {budget}\n"
            + (
                f"tau {s['kendall_tau']:.2f} [{s['tau_lo']:.2f}, {s['tau_hi']:.2f}]"
                if not s["tau_note"]
                else s["tau_note"].partition(":")[0]  # 'no tau', 'cannot tell'
                + f" ({n} methods)"
            ),
        )
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(MaxNLocator(integer=True))
        ax.invert_xaxis()
        ax.invert_yaxis()
    fig.draw_without_rendering()  # the layout settled: the labels are placed in it
    for ax, r in drawn:
        label_points(ax, r["rank_rendered"], r["rank_dataset"], r["method"])
    save(fig, out, ("png",))


STEPS = (0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5)
"""The places `label_points` tries for a label, in lines (8.5 points: 7-point names) up."""


def label_points(ax, x: pd.Series, y: pd.Series, names: pd.Series) -> None:
    """Name each point (x, y) of `ax` beside it, toward the panel's middle, the names of
    tied points in one label; a label that would cover another or a point moves a line
    up or down at a time, with a leader line, inside the panel where it can."""
    renderer, box = ax.figure.canvas.get_renderer(), ax.bbox
    at = ax.transData.transform(np.column_stack([x, y]).astype(float))
    taken = [Bbox.from_bounds(px - 3, py - 3, 6, 6) for px, py in at]  # the points
    tied = pd.DataFrame({"x": x, "y": y, "name": names}).groupby(["x", "y"], sort=False)
    for (px, py), text in tied["name"].agg("\n".join).items():
        right = ax.transData.transform((px, py))[0] < box.x0 + box.width / 2
        dx = 4 if right else -4
        style = {"textcoords": "offset points", "fontsize": 7, "va": "center"}
        style["ha"] = "left" if right else "right"
        for dy in (*(8.5 * k for k in STEPS), None):  # None: no room, beside its point
            label = ax.annotate(text, (px, py), xytext=(dx, dy or 0), **style)
            label.set_in_layout(False)
            at = label.get_window_extent(renderer)
            inside = box.contains(at.x0, at.y0) and box.contains(at.x1, at.y1)
            if dy is None or (inside and not any(at.overlaps(b) for b in taken)):
                break
            label.remove()
        taken.append(at)
        if dy:
            leader = {"arrowstyle": "-", "color": "0.45", "lw": 0.6, "shrinkB": 2}
            line = ax.annotate(
                "", (px, py), xytext=(dx, dy), textcoords="offset points", arrowprops=leader
            )
            line.set_in_layout(False)
