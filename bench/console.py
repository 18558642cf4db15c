"""What the harness tells a person while it works: log lines and tqdm progress bars.

Log lines go to stderr through tqdm, so they appear above an active bar instead of being
glued onto it; bars are shown only when stderr is a terminal.
"""

from __future__ import annotations

import sys

from tqdm import tqdm


def log(msg: str) -> None:
    """One line on stderr, written above any progress bar."""
    tqdm.write(f"bench: {msg}", file=sys.stderr)


def progress(stage: str, total: int) -> tqdm:
    """A progress bar for one stage (ETA included); silent when stderr is not a terminal."""
    return tqdm(
        total=total,
        desc=f"{stage:>8}",
        unit="unit",
        file=sys.stderr,
        disable=not sys.stderr.isatty(),
        dynamic_ncols=True,
        leave=True,
    )
