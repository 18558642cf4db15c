"""What each cache key covers: the definitions and modules its code hash reaches.

    PYTHONPATH=SRC .venv/bin/python benchmarks/hash_coverage.py

SRC is a source tree (this checkout, or one made with `git worktree add /tmp/old <commit>`
for the before/after comparison): the keys of the code before issue 54 (whole modules as
roots, `bench.harness.predict.SHARED_CODE` and `bench.harness.evaluate.SCORING_CODE`) are
read with the cuts that code made. Printed: per key, the definitions (top-level functions,
classes, constants; a module's statements that bind no name counted apart) and modules.
"""

import argparse

from bench.codehash import covered
from bench.frontend import stage
from bench.harness import evaluate, methods, predict  # noqa: F401  (declares every method)
from bench.render.entry import RENDER_CODE
from bench.scenes import catalog
from bench.vocabulary import CODE

METHODS = ("texture", "adaptive", "colmap-b", "cross-view@colmap-soft-b", "oracle")


def content_keys() -> dict:
    """The keys of the code after issue 54: roots are the functions that decide a row."""
    keys = {"shared prediction": covered(predict.SHARED_CODE)}
    keys |= {f"task {t}": covered(predict.task_code(t)) for t in ("tri", "sfm", "pairs")}
    keys["evaluation"] = covered(evaluate.scoring_code())
    keys["front end"] = covered([stage.compute])
    return keys | {f"method {m}": covered(CODE[m]) for m in METHODS}


def module_keys() -> dict:
    """The keys of the code before issue 54: whole modules as roots, others' code cut."""
    every = [f for code in CODE.values() for f in code]
    keys = {
        "shared prediction": covered(
            predict.SHARED_CODE, cut=(predict.SCORING, *predict._method_roots())
        ),
        "evaluation": covered(evaluate.SCORING_CODE, cut=(predict.prediction_hash, *every)),
        "front end": covered([stage.front_end]),
    }
    return keys | {
        f"method {m}": covered(CODE[m], cut=predict._method_roots(but=m)) for m in METHODS
    }


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    keys = content_keys() if hasattr(predict, "task_code") else module_keys()
    table = catalog.generator_of("table")
    others = [g for g in catalog.generator_functions() if g is not table]
    keys["render (table)"] = covered([*RENDER_CODE, table], cut=others)
    for name, parts in keys.items():
        defs = [t for t in parts if t[1] != ""]
        effects = len(parts) - len(defs)
        mods = {m for m, _ in parts}
        extra = f" (+ the effect statements of {effects} modules)" if effects else ""
        print(f"{name:32s} {len(defs):4d} definitions in {len(mods):3d} modules{extra}")


if __name__ == "__main__":
    main()
