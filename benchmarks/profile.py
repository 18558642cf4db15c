"""The profile of a run, from its results folder alone (`manifest.json`, `models/`): wall
seconds per phase with the workers and cores that ran it, each stage's seconds (summed
over the workers), share and cost per row, and how busy the workers were; with
`--duplicates`, the units whose selections coincide with another unit's (the same
selection of the same scene, seed and geometry: its matching and verification could be
shared) and the seconds they spent on them.

    .venv/bin/python benchmarks/profile.py results/published [results/latest ...] [--duplicates]

Several folders print side by side (a profile before and after a change). A manifest
written before the wall seconds were recorded (`wall`, `cluster`) shows its runs stage's
wall (`seconds.runs_wall`) and n/a for what it lacks.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd

RUN_STAGES = ("frontend", "select", "match", "verify", "task", "evaluate_matches", "evaluate")
"""The stages the workers run (the runs phase); `render` runs before them."""
PHASES = ("render", "runs", "report", "total")


def manifest_of(folder: Path) -> dict:
    path = folder / "manifest.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        sys.exit(f"profile: cannot read {path}: {e}")


def profile(manifest: dict) -> pd.Series:
    """One run's profile (manifest sums over its invocations)."""
    seconds, invs = manifest.get("seconds", {}), manifest.get("invocations", [])
    wall = manifest.get("wall") or {
        "render": seconds.get("render"),
        "runs": seconds.get("runs_wall"),
        "report": seconds.get("report"),
        "total": seconds.get("total"),
    }
    rows = sum(i.get("rows", 0) for i in invs)
    workers = sorted({str(i.get("cluster", {}).get("workers", "n/a")) for i in invs})
    cores = sorted({str(i.get("cluster", {}).get("cores", "n/a")) for i in invs})
    out = {
        "rows": rows,
        "workers": ",".join(workers) or "n/a",
        "cores": ",".join(cores) or str(manifest.get("host", {}).get("cpus", "n/a")),
    }
    out |= {f"wall {k} s": wall.get(k, np.nan) for k in PHASES}
    stages = {k: seconds.get(k, 0.0) for k in ("render", *RUN_STAGES)}
    busy = sum(stages[k] for k in RUN_STAGES)
    for k, v in stages.items():
        out[f"{k} s"] = v
    for k in RUN_STAGES:
        out[f"{k} share %"] = 100 * stages[k] / busy if busy else np.nan
    out["runs stages s per row"] = busy / rows if rows else np.nan
    try:
        n = int(out["workers"])
        out["workers busy %"] = 100 * busy / (n * float(wall.get("runs") or np.nan))
    except (TypeError, ValueError):
        out["workers busy %"] = np.nan
    return pd.Series(out)


def duplicates(folder: Path) -> pd.Series:
    """Units whose selection of a (scene, seed, geometry) equals an earlier unit's."""
    seen: dict[tuple, str] = {}
    dup_units, dup_rows, dup_s, units = set(), 0, 0.0, set()
    groups = defaultdict(list)
    for npz in sorted((folder / "models").glob("*/*/prediction-*.npz")):
        grant = npz.stem.removeprefix("prediction-")
        if grant == "peer":
            continue
        record = json.loads((npz.parent / "prediction.json").read_text())
        with np.load(npz) as arrays:
            sel = [arrays[k] for k in sorted(arrays.files) if k.startswith("selection_")]
        digest = hashlib.sha256(b"".join(s.astype(np.int64).tobytes() + b"|" for s in sel))
        key = (npz.parent.parent.name, grant, digest.hexdigest())
        unit = npz.parent.parent.name + "/" + npz.parent.name
        units.add(unit)
        groups[key].append(unit)
        if key in seen:
            dup_units.add(unit)
            jobs = [j for j in record["jobs"].values() if j.get("grant") == grant]
            dup_rows += len(jobs)
            s = record["grants"][grant]["seconds"]
            dup_s += s.get("match", 0.0) + s.get("verify", 0.0)
        else:
            seen[key] = unit
    shared = {k: v for k, v in groups.items() if len(v) > 1}
    return pd.Series(
        {
            "units with a selection": len(units),
            "selections shared by 2+ units": len(shared),
            "units repeating another's selection": len(dup_units),
            "their rows": dup_rows,
            "their match + verify s": dup_s,
            "e.g.": "; ".join(" = ".join(v) for v in list(shared.values())[:3]) or "none",
        }
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("results", nargs="+", type=Path, help="results folders")
    ap.add_argument("--duplicates", action="store_true", help="count coinciding selections")
    args = ap.parse_args(argv)
    table = pd.DataFrame({str(f): profile(manifest_of(f)) for f in args.results})
    pd.set_option("display.width", 200, "display.max_colwidth", 120)
    print(table.map(lambda v: f"{v:.3g}" if isinstance(v, float) else v).to_string())
    if args.duplicates:
        print()
        print(pd.DataFrame({str(f): duplicates(f) for f in args.results}).to_string())


if __name__ == "__main__":
    main()
