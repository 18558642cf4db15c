"""The worker processes of a local Dask cluster (`bench.harness.execute`), set up as they
start, before they take any work: one thread per library, and SIGTERM ignored.

A worker unpickles its setup before it runs anything of the bench, so this module imports
nothing of it: a SIGTERM to the whole process group (`timeout`, systemd) before the setup
ends the starting worker silently (the start is then abandoned, `execute._connect`),
not inside pycolmap's import, whose failure handler (glog's) printed the worker's native
stack.
"""

from __future__ import annotations

import os
import signal
import sys

from distributed import WorkerPlugin


def one_thread_per_library() -> None:
    """Hold this process to one thread in each library that starts its own pool: OpenCV
    (its pool has one thread per core otherwise), and BLAS, OpenMP (COLMAP) and torch,
    whose pools Dask's nanny already sizes to one (`OMP_NUM_THREADS`, `OPENBLAS_NUM_THREADS`
    and `MKL_NUM_THREADS` set before a worker starts; torch reads the first). N workers
    then run N threads on N cores, not N times the cores."""
    import cv2

    cv2.setNumThreads(1)
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"  # for a library loaded later, and for a worker not nannied
    torch = sys.modules.get("torch")  # imported only by the learned methods
    if torch is not None:
        torch.set_num_threads(1)


class WorkerSetup(WorkerPlugin):
    """A worker's setup: SIGTERM ignored, as Ctrl-C is (a signal to the whole process group
    reaches the main process alone, which stops the workers), then one thread per library.
    Ignored again after importing pycolmap, whose import installs glog's failure signal
    handler (SIGTERM included)."""

    name = "bench-worker-setup"

    def setup(self, worker):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        import pycolmap  # noqa: F401

        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        one_thread_per_library()
