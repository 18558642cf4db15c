"""`manifest.json`: the versions, machine, settings and invocations behind a results
folder's rows (`write_manifest`), with each invocation's commit and seconds per stage."""

from __future__ import annotations

import json
import os
import platform
import subprocess
from importlib.metadata import packages_distributions, version

import pandas as pd

from bench import ROOT
from bench.files import write_text_atomic
from bench.frontend.views import Source
from bench.harness.keys import evaluation_hash
from bench.render.entry import entry_meta
from bench.results import MANIFEST, Workspace
from bench.vocabulary import BAG, KEY


def git_commit() -> str:
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "") if sha else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


MODULES = ("mitsuba", "drjit", "numpy", "cv2", "pycolmap", "pandas", "matplotlib", "scipy")
"""The modules whose versions the manifest records."""


def module_versions(modules: tuple[str, ...]) -> dict[str, str]:
    """Per module, the version of the distribution that provides it, named where its name
    differs (`cv2`: `opencv-contrib-python-headless 5.0.0.93`, or whichever OpenCV build is
    installed), and `unknown` where no installed distribution provides it."""
    provided = packages_distributions()
    out = {}
    for module in modules:
        names = sorted(provided.get(module, []))
        out[module] = (
            ", ".join(f"{n} {version(n)}" if n != module else version(n) for n in names)
            or "unknown"
        )
    return out


def write_manifest(ws: Workspace, settings: dict, invocation: dict, rows: pd.DataFrame) -> None:
    """Versions, variant, host, `settings` (the run's) and the invocations that computed the
    rows of `runs.csv`: each with its commit, seconds per stage (`seconds`: the rows' stages
    summed over the workers, and the render stage's scenes), wall seconds per phase (`wall`:
    render, runs, report, total) and what ran it (`cluster`: workers, cores), kept while it
    owns a row (a rerun that computes nothing adds nothing), and their sums."""
    path = ws.results / MANIFEST
    try:
        earlier = json.loads(path.read_text()).get("invocations", [])
    except (OSError, ValueError, AttributeError):
        earlier = []
    live = set(rows["invocation"])
    kept = [
        i
        for i in earlier
        if isinstance(i, dict) and i.get("id") in live and i.get("id") != invocation["id"]
    ]
    if invocation["rows"]:
        kept.append(invocation)
    for inv in kept:
        inv["rows_now"] = int((rows["invocation"] == inv["id"]).sum())
    total: dict[str, float] = {}
    wall: dict[str, float] = {}
    for inv in kept:
        for k, v in inv["seconds"].items():
            total[k] = total.get(k, 0.0) + v
        for k, v in inv.get("wall", {}).items():  # an invocation before the wall was kept has none
            wall[k] = wall.get(k, 0.0) + v
    entries = [ws.renders / k for k in rows["render_key"].unique()]
    metas = [entry_meta(e) for e in entries if Source.kind(e) == "render"]
    manifest = {
        "versions": {"python": platform.python_version(), **module_versions(MODULES)},
        "variant": sorted({m["variant"] for m in metas}),
        "host": {"node": platform.node(), "platform": platform.platform(), "cpus": os.cpu_count()},
        "settings": settings,
        "evaluation_hash": evaluation_hash(),
        "grid": {k: sorted(map(str, rows[k].unique())) for k in KEY if k != BAG},
        "git_commit": sorted({inv["git_commit"] for inv in kept}),
        "invocations": kept,
        "seconds": total,
        "wall": wall,
        "render_entries": sorted(e.name for e in entries),
    }
    write_text_atomic(path, json.dumps(manifest, indent=1))
