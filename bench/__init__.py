"""Rendered-scene benchmark of keypoint selection policies for 3D reconstruction."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
"""Repository root: holds `scenes/`, and the default `renders/` and `results/`."""


class BenchError(Exception):
    """A user-facing error: the CLI prints its message on one line and exits non-zero."""
