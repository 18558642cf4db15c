"""What the harness tells a person while it works: log lines and progress.

Log lines go to stderr through tqdm, so they appear above an active bar instead of being
glued onto it. Progress is a tqdm bar (done / total, rate, time left) on one line that
updates when stderr is a terminal; in a log (stderr redirected), a line every
`LOG_STEP_PCT` percent of the work and at its end, with the same numbers.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

LOG_STEP_PCT = 5
"""In a log, one progress line each time the work done crosses a multiple of this."""


def log(msg: str) -> None:
    """One line on stderr, written above any progress bar."""
    tqdm.write(f"bench: {msg}", file=sys.stderr)


class LogProgress:
    """Progress as log lines (`progress` in a log): tqdm's interface, the lines it prints."""

    def __init__(self, stage: str, total: int, unit: str, initial: int = 0):
        self.stage, self.total, self.unit, self.initial = stage, total, unit, initial
        self.n, self.step, self.start, self.postfix = initial, 0, time.perf_counter(), ""

    def __enter__(self) -> LogProgress:
        return self

    def __exit__(self, *exc) -> None:
        pass

    def set_postfix_str(self, text: str) -> None:
        self.postfix = text

    def reset(self, total: int | None = None) -> None:
        """Start again from 0 (tqdm's `reset`): the rate and time left count from now."""
        self.n, self.step, self.start, self.initial = 0, 0, time.perf_counter(), 0
        self.total = self.total if total is None else total

    def update(self, n: int = 1) -> None:
        self.n += n
        pct = 100 * self.n // max(self.total, 1)
        if pct // LOG_STEP_PCT > self.step or self.n >= self.total:
            self.step = pct // LOG_STEP_PCT
            elapsed = time.perf_counter() - self.start
            rate = (self.n - self.initial) / elapsed if elapsed > 0 else 0.0
            left = (self.total - self.n) / rate if rate else 0.0
            log(
                f"{self.stage}: {self.n}/{self.total} {self.unit} ({pct} %), "
                f"{rate:.2f} {self.unit}/s, {tqdm.format_interval(left)} left"
                + (f" ({self.postfix})" if self.postfix else "")
            )


class NoProgress(LogProgress):
    """A stage with nothing to show (a dataset run renders nothing): no line at all."""

    def update(self, n: int = 1) -> None:
        self.n += n


def progress(stage: str, total: int, unit: str = "unit", shown: bool = True, initial: int = 0):
    """The progress of one stage: a bar on a terminal, else log lines (module docstring);
    nothing where not `shown`. `initial`: the work found done before the stage began
    (cached), counted as done and never in the rate, which is the stage's own work over
    the time it took."""
    if not shown:
        return NoProgress(stage, total, unit, initial)
    if not sys.stderr.isatty():
        return LogProgress(stage, total, unit, initial)
    return tqdm(
        total=total,
        initial=initial,
        desc=f"{stage:>8}",
        unit=unit,
        file=sys.stderr,
        dynamic_ncols=True,
        leave=True,
    )
