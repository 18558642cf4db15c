"""`bench upgrade`: a results folder written by an older bench, brought up to date."""

from __future__ import annotations

import argparse

from bench.cli.common import LATEST, results_arg

HELP = "bring a results folder written by an older bench up to date, in place"
DESCRIPTION = (
    "Rename runs.csv's `policy` column `method` (each row's checksum recomputed where it "
    "held), and, where RESULTS/vocabulary.json lacks what this bench records of its "
    "methods, tasks and metrics (a method's kind, a task's metrics, a metric's range and "
    "direction), record this bench's declarations of the same names; write the rows of a "
    "task without tracks (pairs) once per unit, protocol none, where an older bench wrote "
    "one per track protocol; where the folder has no origin.json and its manifest names one "
    "commit whose code computed every row (each row's hashes checked against it), record "
    "its origin (what a published snapshot is judged by: docs/results.md, 'Baselines'). No "
    "row is computed again; run `bench plot` afterwards to rewrite the tables."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    results_arg(parser, LATEST, f"results folder (default: ./{LATEST})")


def run(args: argparse.Namespace) -> None:
    from bench import BenchError
    from bench.results import holding
    from bench.unit.declared import package_vocabulary
    from bench.upgrades import refuse_damage, upgrade

    if not args.results.is_dir():  # before the lock, which would be "cannot write"
        raise BenchError(f"{args.results} not found: give a results folder of `bench run`")
    with holding(args.results):
        changed = upgrade(args.results, package_vocabulary())
        print("\n".join(f"{args.results}: {c}" for c in changed), end="\n" if changed else "")
        refuse_damage(args.results)  # what it changed is said; damage is not "up to date"
        recorded, why = _origin(args.results)
    if recorded or why:
        print(f"{args.results}: {recorded or why}")
    if not changed and not recorded:
        print(f"{args.results} is up to date; nothing changed")


def _origin(results) -> tuple[str, str]:
    """Record the folder's origin where it has none and its rows prove one commit's:
    (what was recorded, or why nothing was)."""
    import json

    from bench import BenchError
    from bench.cli.common import folder_origin
    from bench.harness.origin import write_origin
    from bench.results import MANIFEST, ORIGIN

    if (results / ORIGIN).is_file() or not (results / MANIFEST).is_file():
        return "", ""
    commits = json.loads((results / MANIFEST).read_text()).get("git_commit", [])
    if len(commits) != 1:
        return "", f"no {ORIGIN}: its rows were computed at {len(commits)} commits, not one"
    commit = commits[0].removesuffix("-dirty")  # the rows' hashes say whether it is the code
    try:
        origin = folder_origin(results, commit)
    except BenchError as e:
        return "", f"no {ORIGIN}: {e}"
    write_origin(results, origin)
    return f"{ORIGIN}: recorded, every row checked against commit {origin['commit'][:12]}", ""
