"""The render-noise levers on the same footing (issue 40): the benchmark's slice under each
setting, and the lever table from their rows.

    # the slice under each setting: results/levers/<setting>/ (a `bench run` each)
    .venv/bin/python benchmarks/levers.py run --out results/levers \
        [--settings 25,25:3,128,25:2,64,256,25/0.02] [--workers N] [--budget-s 480]
    # the lever table: the slices' rows against the datasets' (tau), one line per setting
    .venv/bin/python benchmarks/levers.py table results/levers/* \
        [--dataset-results results/datasets] [--out levers.csv]

A setting is `SPP[:DENOISE][/CONTRAST]` (`render.spp`, `render.denoise`,
`detector.sift_contrast`); the slice is every scene, seeds 0 and 1, B = 256 and 512, the
sfm and pairs tasks under the headline protocol, every default method. `run` computes
the settings in the order given and starts none after `--budget-s` seconds.

The table, per setting (nothing recomputed; the tables' own statistics):
- `zero_pct_<B>`: the share of the budgeted policies' sfm cells (scene, seed) at mAA <=
  0.05 (the peers, the oracle and the whole-pool references left out);
- `<task> <policy>-colmap-b @B`: each budgeted policy minus `colmap-b` in sfm mAA and in
  pairs AUC@10, pooled over the scenes, with the stratified 95% interval
  (`bench.report.stats.paired_difference`);
- `tau <dataset> <metric> @B`: Kendall's tau of the slice's ranking against each dataset's
  (`bench.report.transfer`), with its bootstrap interval.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from bench.binding import read_vocabulary
from bench.report.stats import paired_difference
from bench.report.tables import headline_frame, solvable
from bench.report.transfer import kendall_tau, tau_interval
from bench.runs import read_runs
from bench.vocabulary import Vocabulary

PEER = "colmap-b"
METRICS = {"sfm": "sfm_maa", "pairs": "pairs_auc_10"}
ZERO = 0.05
BUDGETS = (256, 512)


def flags(setting: str) -> list[str]:
    """`bench run` options of a setting `SPP[:DENOISE][/CONTRAST]`."""
    render, _, contrast = setting.partition("/")
    spp, _, denoise = render.partition(":")
    out = ["--spp", spp, "--denoise", denoise or "0"]
    return out + (["--set", f"detector.sift_contrast={contrast}"] if contrast else [])


def run(args) -> None:
    start = time.perf_counter()
    for setting in args.settings.split(","):
        if time.perf_counter() - start > args.budget_s:
            print(f"levers: {setting} not started (past --budget-s)", flush=True)
            continue
        folder = args.out / setting.replace(":", "d").replace("/", "c")
        cmd = [sys.executable, "-m", "bench", "run", "--results", str(folder)]
        cmd += ["--seeds", "0,1", "--budget", ",".join(map(str, BUDGETS))]
        cmd += ["--tasks", "sfm,pairs", "--protocols", "multiview", "--workers", str(args.workers)]
        cmd += ["--renders", str(args.renders), *flags(setting), *args.extra]
        t = time.perf_counter()
        done = subprocess.run(cmd).returncode
        print(f"levers: {setting} in {time.perf_counter() - t:.0f} s (exit {done})", flush=True)


def budgeted(frame: pd.DataFrame, vocab: Vocabulary) -> list[str]:
    """The budgeted policies (baselines and contenders) present."""
    return [m for m in vocab.with_role("baseline", "contender") if m in set(frame["method"])]


def _values(frame: pd.DataFrame, metric: str, vocab: Vocabulary, budget: int) -> pd.DataFrame:
    part = solvable(frame, metric, vocab)
    part = part[part["budget"] == budget]
    return part.pivot(index=["scene", "seed"], columns="method", values=metric).astype(float)


def setting_row(folder: Path, datasets: list[pd.DataFrame]) -> dict:
    vocab = read_vocabulary(folder)
    frame = headline_frame(read_runs(folder / "runs.csv"), vocab)
    row: dict = {"setting": folder.name}
    policies = budgeted(frame, vocab)
    for budget in BUDGETS:
        sfm = _values(frame, METRICS["sfm"], vocab, budget)
        cells = sfm[policies].fillna(0).to_numpy().ravel()
        row[f"zero_pct_{budget}"] = 100.0 * float((cells <= ZERO).mean())
        for task, metric in METRICS.items():
            wide = _values(frame, metric, vocab, budget)
            scenes = wide.index.get_level_values("scene").to_numpy()
            for p in policies:
                res = paired_difference(wide[p] - wide[PEER], scenes, False)
                row[f"{task} {p}-{PEER} @{budget}"] = res["mean_diff"]
                row[f"{task} {p}-{PEER} @{budget} lo"] = res["lo"]
                row[f"{task} {p}-{PEER} @{budget} hi"] = res["hi"]
    for ds in datasets:
        for task, metric in METRICS.items():
            for budget in BUDGETS:
                mine = _values(frame, metric, vocab, budget).mean()
                theirs = ds.attrs["means"][metric, budget]
                methods = [m for m in mine.index if m in theirs.index and m != "oracle"]
                x, y = theirs[methods].to_numpy(), mine[methods].to_numpy()
                name = f"tau {ds.attrs['name']} {task} @{budget}"
                row[name] = kendall_tau(x, y) if len(methods) >= 6 else math.nan
                row[f"{name} lo"], row[f"{name} hi"] = tau_interval(x, y)
    return row


def dataset_means(folder: Path) -> list[pd.DataFrame]:
    """Per dataset of a results folder, the mean of each ranking metric per method."""
    vocab = read_vocabulary(folder)
    frame = headline_frame(read_runs(folder / "runs.csv"), vocab, dataset=True)
    out = []
    for name, rows in frame.groupby("scene"):
        ds = pd.DataFrame()
        ds.attrs["name"] = name
        ds.attrs["means"] = {
            (m, b): rows[rows["budget"] == b].groupby("method")[m].mean()
            for m in METRICS.values()
            for b in BUDGETS
        }
        out.append(ds)
    return out


def table(args) -> None:
    datasets = dataset_means(args.dataset_results) if args.dataset_results else []
    rows = pd.DataFrame([setting_row(Path(f), datasets) for f in args.folders])
    if args.out:
        rows.to_csv(args.out, index=False)
    shown = [c for c in rows if not c.endswith((" lo", " hi"))]
    print(rows[shown].set_index("setting").T.to_string(float_format="%.3f"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--out", type=Path, default=Path("results/levers"))
    r.add_argument("--settings", default="25,25:3,128,25:2,64,256,25/0.02")
    r.add_argument("--workers", type=int, default=2)
    r.add_argument("--renders", type=Path, default=Path("renders"))
    r.add_argument("--budget-s", type=float, default=math.inf)
    t = sub.add_parser("table")
    t.add_argument("folders", nargs="+")
    t.add_argument("--dataset-results", type=Path, default=None)
    t.add_argument("--out", type=Path, default=None)
    args, extra = ap.parse_known_args()
    args.extra = [
        e for e in extra if e != "--"
    ]  # more `bench run` options (a smoke run: --quick --scenes table)
    run(args) if args.command == "run" else table(args)


if __name__ == "__main__":
    main()
