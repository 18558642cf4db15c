"""Alias the hashes of one run's rows to another's, once their values are proven identical.

    .venv/bin/python benchmarks/alias_hashes.py BEFORE/runs.csv AFTER/runs.csv

BEFORE is a run of the code before a change that keeps every value (a refactoring, a
mending), AFTER the same grid run by the code after it, into a fresh folder. The two are
compared by `benchmarks/compare_runs.py`; only if they hold the same rows and no metric
column differs at all are the (old, new) pairs of their `prediction_hash`,
`evaluation_hash` and render keys added to `bench/hash_aliases.json` (`bench.codehash.
accepted`), so that folders and render caches of the code before are current for the code
after. Anything else: one line, exit 2, nothing written.
"""

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
ALIASES = ROOT / "bench" / "hash_aliases.json"
KEY = ["scene", "seed", "method", "budget", "task", "protocol"]


def fail(why: str) -> None:
    print(f"alias_hashes: {why}; nothing written", file=sys.stderr)
    sys.exit(2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="runs.csv of the code before")
    ap.add_argument("after", type=Path, help="runs.csv of the code after, the same grid")
    args = ap.parse_args()
    for p in (args.before, args.after):
        if not p.is_file():
            fail(f"{p} not found")
    cmd = [sys.executable, str(ROOT / "benchmarks" / "compare_runs.py"), str(args.before)]
    done = subprocess.run([*cmd, str(args.after)], capture_output=True, text=True)
    print(done.stdout, end="")
    lines = done.stdout.splitlines()
    if done.returncode or not lines:
        fail(f"compare_runs.py failed: {done.stderr.strip()[-500:]}")
    sizes = re.findall(r"\d+", lines[0])  # rows: A vs B, common C
    if not (len(set(sizes)) == 1 and int(sizes[0]) > 0):
        fail(f"the runs do not hold the same rows ({lines[0]})")
    differing = [line.strip() for line in lines if line.startswith("  ")]
    if differing:
        fail(f"the values differ ({differing[0]})")
    a, b = (pd.read_csv(p, dtype=str, keep_default_na=False) for p in (args.before, args.after))
    both = a.merge(b, on=KEY, suffixes=("_old", "_new"))
    pairs = set()
    for column in ("prediction_hash", "evaluation_hash", "render_key"):
        for old, new in zip(both[f"{column}_old"], both[f"{column}_new"]):
            if column == "render_key":  # an entry's name, <scene>-s<seed>-<key>
                old, new = old.rpartition("-")[2], new.rpartition("-")[2]
            if old != new:
                pairs.add((old, new))
    known = {tuple(p) for p in json.loads(ALIASES.read_text())} if ALIASES.exists() else set()
    tmp = ALIASES.with_suffix(f".tmp{os.getpid()}")
    lines = ",\n".join(json.dumps(list(p)) for p in sorted(known | pairs))
    tmp.write_text(f"[\n{lines}\n]\n")
    tmp.replace(ALIASES)
    print(f"{len(pairs - known)} alias(es) added to {ALIASES.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
