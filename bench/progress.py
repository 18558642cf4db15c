"""A small progress bar on stderr: what is being done, how far, and the time left."""

from __future__ import annotations

import sys
import time


class Progress:
    """`with Progress("runs", total) as bar: bar.step("table s0 adaptive")`."""

    def __init__(self, stage: str, total: int, width: int = 24):
        self.stage, self.total, self.width = stage, max(total, 0), width
        self.done, self.t0 = 0, time.perf_counter()
        self.tty = sys.stderr.isatty()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        if self.tty:
            print(file=sys.stderr)

    def step(self, what: str) -> None:
        """Mark one more unit of work done (`what` names it)."""
        self.done += 1
        elapsed = time.perf_counter() - self.t0
        left = elapsed / self.done * (self.total - self.done)
        filled = round(self.width * self.done / self.total) if self.total else self.width
        bar = "#" * filled + "." * (self.width - filled)
        line = f"{self.stage:>8} [{bar}] {self.done}/{self.total} {what} | {_hms(elapsed)} elapsed, ~{_hms(left)} left"
        print(
            ("\r" + line.ljust(110)) if self.tty else line,
            end="" if self.tty else "\n",
            file=sys.stderr,
            flush=True,
        )


def _hms(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    return f"{m}m{s:02d}s" if m else f"{s}s"
