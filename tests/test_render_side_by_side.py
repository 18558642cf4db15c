"""Scenes rendered side by side (`bench.render.entry.render_scenes`): each scene once, with
its own result, in processes of their own; one process renders in this one, in order."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.render.entry import render_scenes
from tests.conftest import default_sigint
from tests.test_render import assert_no_partial_work


def fake_render(scene: str, seed: int) -> Path:
    """A render that says where it ran (importable by a spawned process)."""
    return Path(f"{scene}-s{seed}") / str(os.getpid())


SCENES = [("table", 0), ("facade", 1), ("corridor", 0)]


def dying_render(scene: str, seed: int) -> Path:
    """A render whose process is killed in the middle of the facade (as the kernel's OOM
    killer would), the others quick."""
    if scene == "facade":
        os.kill(os.getpid(), signal.SIGKILL)
    return Path(f"{scene}-s{seed}")


def test_a_rendering_process_that_dies_is_one_error_never_a_hang():
    """Each process has a pipe of its own (no lock shared with a process that can die, as
    `multiprocessing.Pool`'s queues were): a killed one is one line, the others stopped."""
    from bench import BenchError

    t = time.monotonic()
    with pytest.raises(BenchError, match=r"a rendering process died \(exit code -9\)"):
        list(render_scenes(SCENES, dying_render, 2))
    assert time.monotonic() - t < 30


def test_one_process_renders_in_order_in_this_one():
    out = list(render_scenes(SCENES, fake_render, 1))
    assert [s for s, _, _ in out] == SCENES
    assert [e for _, e, _ in out] == [Path(f"{n}-s{d}") / str(os.getpid()) for n, d in SCENES]
    assert all(seconds >= 0 for _, _, seconds in out)


def test_scenes_side_by_side_render_each_once_elsewhere():
    out = list(render_scenes(SCENES, fake_render, 2))
    assert sorted(s for s, _, _ in out) == sorted(SCENES)
    for (scene, seed), entry, _ in out:
        assert entry.parent == Path(f"{scene}-s{seed}") and entry.name != str(os.getpid())


@pytest.mark.parametrize(
    "sig, code, said", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")]
)
def test_a_signal_to_the_group_while_scenes_render_side_by_side_stops_in_one_line(
    tmp_path, sig, code, said
):
    """`bench run --workers 2` renders two scenes in two processes of their own group; a
    signal to the run's group (a terminal, `timeout`) reaches the run alone, which stops
    them between views: one line, the views rendered whole, no lock or temporary folder."""
    renders = tmp_path / "renders"
    cmd = [sys.executable, "-m", "bench", "run", "--quick", "--scenes", "table,facade"]
    cmd += ["--workers", "2", "--results", str(tmp_path / "r"), "--renders", str(renders)]
    proc = subprocess.Popen(
        cmd, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=default_sigint
    )
    deadline = time.monotonic() + 120
    while not list(renders.glob("views/.tmp-*")) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.05)
    os.killpg(proc.pid, getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    lines = err.strip().splitlines()
    assert proc.returncode == code, err
    assert lines[-1] == f"bench: {said}; finished work is kept", err
    assert all(line.startswith("bench: ") for line in lines), err
    assert_no_partial_work(renders)
