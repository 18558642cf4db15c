"""`bench scenes`: the scene types and their parameters."""

from __future__ import annotations

import argparse

HELP = "list the scene types and their parameters"
DESCRIPTION = (
    "List every scene type (scenes/<name>.toml) with its description and each parameter's "
    "value and meaning."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> None:
    from bench.scenes.spec import load_spec, scene_names

    for name in scene_names():
        spec = load_spec(name)
        print(f"{name}: {spec.description}")
        for k, v in spec.params.items():
            print(f"    {k} = {v!r:<10} {spec.docs.get(k, '')}")
