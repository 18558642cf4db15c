"""Table 3 and `figure_views.png`: the next-views task (`bench.vocabulary.NEXT_VIEWS`), from
`runs.csv` alone, and their section of the results page.

* `table3.csv`: per scene (and all scenes pooled), budget, score (`completeness`: the tri
  task's accurate completeness, in points of the path's reconstructable points; `maa`:
  the sfm task's pose mAA) and views added k, each view chooser's mean gain over its
  initial capture with the stratified 95% interval over its (scene, seed) units
  (`bench.report.stats`), and its paired difference from every baseline chooser (role
  `baseline`: random-view, farthest-view, gap-view) over the units both ran, with the
  interval and wins / ties / losses; one row per (chooser, baseline), the headline track
  protocol's rows.
* `figure_views.png`: each score against the views added, per chooser (mean and 95% band),
  pooled and per scene, at the headline budget.
* `page_section`: Table 3 pooled at the headline budget, whether each contender's gain
  beats each baseline's (paired interval above 0) or not and by how much, whether the view
  oracle bounds every chooser, and the gains per scene.
"""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from bench.report.figures import headline_budget, save  # noqa: E402
from bench.report.stats import paired_difference, stratified_interval  # noqa: E402
from bench.report.tables import within  # noqa: E402
from bench.report.text import ci, num, table  # noqa: E402
from bench.results import TABLE3
from bench.vocabulary import HEADLINE, NEXT_VIEWS, Vocabulary  # noqa: E402

GAIN = re.compile(r"(?P<score>.+)_gain_k(?P<k>\d+)")
POOLED = "all scenes"


def _rows(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """The next-views task's rows under the headline protocol."""
    if NEXT_VIEWS not in vocab.tasks or "task" not in df:
        return df.iloc[0:0]
    return df[(df["task"] == NEXT_VIEWS) & (df["protocol"] == HEADLINE[1])]


def gains(rows: pd.DataFrame, vocab: Vocabulary) -> list[tuple[str, str, int]]:
    """(metric, score, k) of every gain metric the rows hold, by score then k."""
    found = [(m, GAIN.fullmatch(m)) for m in vocab.tasks[NEXT_VIEWS].metrics if m in rows]
    out = [(m, g["score"], int(g["k"])) for m, g in found if g]
    return sorted(out, key=lambda x: (x[1], x[2]))


def table3(df: pd.DataFrame, vocab: Vocabulary) -> pd.DataFrame:
    """Table 3 (module docstring); empty without next-views rows."""
    rows = _rows(df, vocab)
    if rows.empty:
        return pd.DataFrame()
    methods = sorted(dict.fromkeys(rows["method"]), key=vocab.order)
    baselines = [m for m in methods if m in vocab.with_role("baseline")]
    out = []
    for budget in sorted(rows["budget"].unique()):
        for scope in [*dict.fromkeys(rows["scene"]), POOLED]:
            part = rows[rows["budget"] == budget]
            part = part if scope == POOLED else part[part["scene"] == scope]
            for metric, score, k in gains(rows, vocab):
                wide = part.pivot(index=["scene", "seed"], columns="method", values=metric)
                strata = wide.index.get_level_values("scene").to_numpy()
                for method in (m for m in methods if m in wide):
                    x = wide[method].to_numpy(float)
                    mean, lo, hi, note = stratified_interval(x, strata)
                    lo, hi = within(lo, hi, vocab.range_of(metric))
                    row = {"scene": scope, "budget": budget, "score": score, "k": k}
                    row |= {"method": method, "runs": int(np.isfinite(x).sum())}
                    row |= {"gain": mean, "gain_lo": lo, "gain_hi": hi, "gain_note": note}
                    for base in [b for b in baselines if b != method and b in wide] or [""]:
                        d = x - wide[base].to_numpy(float) if base else []
                        res = paired_difference(d, strata if base else [], False)
                        out.append(
                            row
                            | {"baseline": base, "diff": res.pop("mean_diff")}
                            | {f"diff_{f}": res.pop(f) for f in ("lo", "hi", "note")}
                            | res
                        )
    return pd.DataFrame(out)


def figure_views(df: pd.DataFrame, vocab: Vocabulary, out: Path) -> bool:
    """Each score against the views added (k = 0 and the gains' k), per chooser, pooled and
    per scene, at the headline budget; whether there was anything to draw."""
    rows = _rows(df, vocab)
    if rows.empty:
        return False
    budget = headline_budget(rows)
    rows = rows[rows["budget"] == budget]
    ks = sorted({k for _, _, k in gains(rows, vocab)})
    scores = list(dict.fromkeys(s for _, s, _ in gains(rows, vocab)))
    scopes = [POOLED, *dict.fromkeys(rows["scene"])]
    methods = sorted(dict.fromkeys(rows["method"]), key=vocab.order)
    width = max(3.6 * len(scopes), 11.0)
    fig, axes = plt.subplots(
        len(scores), len(scopes), figsize=(width, 3.3 * len(scores) + 0.8), squeeze=False
    )
    for r, score in enumerate(scores):
        cols = [f"{score}_k{k}" for k in (0, *ks) if f"{score}_k{k}" in rows]
        for c, scope in enumerate(scopes):
            ax = axes[r, c]
            part = rows if scope == POOLED else rows[rows["scene"] == scope]
            for n, method in enumerate(methods):
                mine = part[part["method"] == method]
                stats = [stratified_interval(mine[col], mine["scene"]) for col in cols]
                x = [int(col.rsplit("_k", 1)[1]) for col in cols]
                mean, lo, hi = (np.array([s[i] for s in stats], float) for i in range(3))
                reference = vocab.methods[method].role == "reference"
                line = ax.plot(
                    x,
                    mean,
                    marker="o",
                    label=vocab.label(method),
                    color="black" if reference else plt.cm.tab10(n % 10),
                    linestyle=":" if reference else "-",
                )
                ax.fill_between(x, lo, hi, color=line[0].get_color(), alpha=0.12)
            title = vocab.metrics[cols[0]].title.split(",")[0] if cols else score
            ax.set_title(f"{scope}: {title}", fontsize=9)
            ax.set_xticks([0, *ks])
            ax.set_xlabel("views added")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(f"Next views: score against the views added (budget {budget}; mean and 95% band)")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    save(fig, out, ("png",))
    return True


def verdict(r: pd.Series) -> str:
    """Whether a paired difference's interval lies above 0, below, or holds it."""
    if pd.isna(r["diff_lo"]):
        return f"no interval ({r['diff_note']})"
    if r["diff_lo"] > 0:
        return "above 0"
    return "below 0" if r["diff_hi"] < 0 else "not separated"


def page_section(results: Path, vocab: Vocabulary) -> list[str]:
    """Table 3's section of the results page (module docstring), from `table3.csv`."""
    path = Path(results) / TABLE3
    if not path.is_file():
        return []
    t3 = pd.read_csv(path, keep_default_na=False, na_values=[""])
    budget = headline_budget(t3)
    at = t3[(t3["budget"] == budget) & (t3["scene"] == POOLED)]
    baselines = sorted((b for b in set(at["baseline"].dropna()) if b), key=vocab.order)
    scores = list(dict.fromkeys(at["score"]))
    names = {s: vocab.metrics[f"{s}_gain_k1"].title.split(",")[0] for s in scores}
    out = [f"## Table 3: next views, gain over the initial capture (budget {budget})", ""]
    out += [
        "Mean gain over the (scene, seed) units with its 95% interval, and the paired "
        "difference from each baseline chooser (`table3.csv` has every budget and scene). "
        "The oracle picks by the tri completeness where there is per-pixel truth, else by "
        "the sfm mAA: it bounds the other score only where its choice happens to.",
        "",
    ]
    header = ["chooser", "k", *names.values()]
    header += [f"{names[s]} − {b}" for b in baselines for s in scores]
    body = []
    for (method, k), g in at.groupby(["method", "k"], sort=False):
        one = {s: g[g["score"] == s].iloc[0] for s in scores if (g["score"] == s).any()}
        cells = [ci(r["gain"], r["gain_lo"], r["gain_hi"], r["gain_note"]) for r in one.values()]
        for b in baselines:
            for s in scores:
                d = g[(g["score"] == s) & (g["baseline"] == b)]
                cells.append(
                    ci(*d.iloc[0][["diff", "diff_lo", "diff_hi", "diff_note"]]) if len(d) else "—"
                )
        body.append([vocab.label(method), str(k), *cells])
    out += table(header, body) + [""]
    contenders = [m for m in dict.fromkeys(at["method"]) if m in vocab.with_role("contender")]
    lines = []
    for m in contenders:
        for _, r in at[(at["method"] == m) & at["baseline"].isin(baselines)].iterrows():
            lines.append(
                f"- {m} − {r['baseline']}, {r['score']}, k = {r['k']}: "
                f"{ci(r['diff'], r['diff_lo'], r['diff_hi'])} ({verdict(r)}; "
                f"{r['wins']}/{r['ties']}/{r['losses']} w/t/l)"
            )
    references = [m for m in dict.fromkeys(at["method"]) if m in vocab.with_role("reference")]
    for ref in references:
        for (score, k), g in at.groupby(["score", "k"], sort=False):
            means = g.drop_duplicates("method").set_index("method")["gain"]
            others = means.drop(ref, errors="ignore").dropna()
            if ref in means and len(others):
                gap = means[ref] - others.max()
                lines.append(
                    f"- {ref} bounds every chooser in {score} at k = {k}: "
                    + ("yes" if gap >= 0 else f"no, {others.idxmax()} is {num(-gap)} above it")
                )
    out += lines + [""] if lines else []
    scenes = [s for s in dict.fromkeys(t3["scene"]) if s != POOLED]
    per = t3[(t3["budget"] == budget) & t3["scene"].isin(scenes)].drop_duplicates(
        ["scene", "method", "score", "k"]
    )
    if len(per):
        cols = list(dict.fromkeys(zip(per["score"], per["k"])))
        out += ["Mean gain per scene:", ""]
        body = [
            [scene, vocab.label(method)]
            + [num(g[(g["score"] == s) & (g["k"] == k)]["gain"].mean()) for s, k in cols]
            for (scene, method), g in per.groupby(["scene", "method"], sort=False)
        ]
        out += table(["scene", "chooser", *[f"{s}, k = {k}" for s, k in cols]], body) + [""]
    return out
