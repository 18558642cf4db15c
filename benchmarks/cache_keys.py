"""Which rows a small change recomputes (issue 29): a tiny grid run cold, then again after
each change, on a copy of the source tree (the package is never edited in place).

    .venv/bin/python benchmarks/cache_keys.py [--source DIR] [--out DIR]

The changes, in order: a docstring and a comment edited; a helper of three policies
renamed in every module (`capped_greedy`); one policy edited (`texture`);
a policy added (`texture-low`, in the grid from then on); `adaptive-loop`'s loop_rounds
changed (`--set adaptive-loop.loop_rounds=1`; on a source tree without per-method
settings `--set policy.loop_rounds=1 --overwrite`, which that code requires); a scene
added (`table2`, the table generator under another name). Printed: per step the rows
predicted again (P), scored again only (S), new (+) or reused (.), the scenes whose
render key the change altered (what any later run re-renders), the renders made and the
seconds; a grid of rows x steps. `--source` runs another checkout (e.g. one made
with `git worktree add /tmp/old 105c362`) for the before/after comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
GRID = [
    "--quick",
    "--seeds",
    "0",
    "--budget",
    "64",
    "--tasks",
    "tri",
    "--protocols",
    "multiview",
    "--workers",
    "1",
]
POLICIES = "random,texture,adaptive-fast,adaptive-loop"
NEW_POLICY = """

@policy("texture-low", "Texture, lowest first", role="baseline", reads=("texture",))
def texture_low_policy(inp, budget, rng, cfg):
    return strongest_first(-inp.signals.texture)[:budget]
"""
NEW_SCENE = """

@generator("table2")
def table2(p: dict, rng: np.random.Generator, width: int, height: int, views: int):
    return table(p, rng, width, height, views)
"""


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    if old not in text:
        sys.exit(f"cannot edit {path}: {old!r} not found")
    path.write_text(text.replace(old, new, 1))


def rename(root: Path, old: str, new: str) -> None:
    """`old` renamed `new` (a whole word) in every module under `root`."""
    for path in root.rglob("*.py"):
        text = path.read_text()
        if re.search(rf"\b{old}\b", text):
            path.write_text(re.sub(rf"\b{old}\b", new, text))


def run(src: Path, work: Path, extra: list[str], scenes: str, policies: str) -> float:
    cmd = [sys.executable, "-m", "bench", "run", *GRID, "--scenes", scenes]
    cmd += ["--methods", policies, "--results", str(work / "results")]
    cmd += ["--renders", str(work / "renders"), *extra]
    t = time.perf_counter()
    env = os.environ | {"PYTHONPATH": str(src)}
    done = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr[-3000:]}")
    return time.perf_counter() - t


KEYS = """
import json, sys
from bench.render.config import QUICK_RENDER
from bench.render.entry import render_key
from bench.scenes.spec import load_spec, scene_names
print(json.dumps({s: render_key(load_spec(s), 0, QUICK_RENDER, "scalar_rgb") for s in scene_names()}))
"""


def render_keys(src: Path) -> dict[str, str]:
    """Each scene's render key (seed 0, --quick) under the source tree `src`."""
    env = os.environ | {"PYTHONPATH": str(src)}
    cmd = [sys.executable, "-c", KEYS]
    done = subprocess.run(cmd, cwd=src, env=env, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"render keys failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout)


def entries(work: Path) -> set[str]:
    return {p.name for p in (work / "renders").iterdir() if p.is_dir() and "-s" in p.name}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, default=ROOT, help="source tree (has bench/)")
    parser.add_argument("--out", type=Path, default=None, help="keep the work folder here")
    args = parser.parse_args()
    work = args.out or Path(tempfile.mkdtemp(prefix="cache-keys-"))
    src = work / "src"
    shutil.rmtree(src, ignore_errors=True)
    shutil.copytree(args.source / "bench", src / "bench")
    shutil.copytree(args.source / "scenes", src / "scenes")
    new_code = (src / "bench" / "codehash.py").is_file()
    pol = src / "bench" / "frontend" / "policies.py"
    steps = [
        ("cold", None, "table,facade", POLICIES, []),
        (
            "docstring",
            lambda: (
                edit(pol, '"""The B candidates of highest texture."""', '"""Top-B texture."""'),
                edit(
                    src / "bench" / "frontend" / "signals.py",
                    "from __future__ import annotations",
                    "from __future__ import annotations  # a comment",
                ),
                edit(
                    src / "bench" / "camera.py",
                    "Pinhole cameras in the OpenCV/COLMAP convention",
                    "Pinhole cameras, in the OpenCV and COLMAP convention",
                ),
            ),
            "table,facade",
            POLICIES,
            [],
        ),
        (
            "rename",
            lambda: rename(src / "bench", "capped_greedy", "greedy_under_cap"),
            "table,facade",
            POLICIES,
            [],
        ),
        (
            "edit texture",
            lambda: edit(
                pol,
                "return strongest_first(inp.signals.texture)[:budget]",
                "return strongest_first(1.0 * inp.signals.texture)[:budget]",
            ),
            "table,facade",
            POLICIES,
            [],
        ),
        (
            "add policy",
            lambda: pol.write_text(pol.read_text() + NEW_POLICY),
            "table,facade",
            POLICIES + ",texture-low",
            [],
        ),
        (
            "loop_rounds",
            None,
            "table,facade",
            POLICIES + ",texture-low",
            ["--set", "adaptive-loop.loop_rounds=1"]
            if new_code
            else ["--set", "policy.loop_rounds=1", "--overwrite"],
        ),
        (
            "add scene",
            lambda: (
                (src / "bench" / "scenes" / "generators.py").write_text(
                    (src / "bench" / "scenes" / "generators.py").read_text() + NEW_SCENE
                ),
                shutil.copy(src / "scenes" / "table.toml", src / "scenes" / "table2.toml"),
            ),
            "table,facade,table2",
            POLICIES + ",texture-low",
            ["--set", "adaptive-loop.loop_rounds=1"]
            if new_code
            else ["--set", "policy.loop_rounds=1"],
        ),
    ]
    grid, summary, previous = {}, [], None
    for name, change, scenes, policies, extra in steps:
        keys = render_keys(src)
        if change:
            change()
        rekeyed = [k for k, v in render_keys(src).items() if keys.get(k) != v]
        before = entries(work) if (work / "renders").is_dir() else set()
        seconds = run(src, work, extra, scenes, policies)
        rows = pd.read_csv(work / "results" / "runs.csv", dtype=str)
        rows["row"] = rows["scene"] + " " + rows["method"]
        now = rows.set_index("row")
        status = {}
        for row, r in now.iterrows():
            if previous is None or row not in previous.index:
                status[row] = "+"
            elif r["invocation"] == previous.loc[row, "invocation"]:
                status[row] = "."
            elif r["prediction_hash"] != previous.loc[row, "prediction_hash"]:
                status[row] = "P"
            else:
                status[row] = "S"
        grid[name] = status
        made = sorted(entries(work) - before)
        counts = {k: sum(v == k for v in status.values()) for k in "P+S."}
        summary.append(
            f"{name:13s} predicted again {counts['P']:2d}, new {counts['+']:2d}, scored again "
            f"{counts['S']:2d}, reused {counts['.']:2d}; render keys changed: "
            f"{', '.join(rekeyed) or 'none'}; renders made: "
            f"{', '.join(m.rsplit('-', 1)[0] for m in made) or 'none'}; {seconds:.0f} s"
        )
        previous = now
    table = pd.DataFrame(grid).fillna("").sort_index()
    print(f"source: {args.source}")
    print("\n".join(summary))
    print("\nP predicted again, S scored again, + new, . reused")
    print(table.to_string())
    if args.out is None:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
