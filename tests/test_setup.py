"""The set-up and the suite itself: every dependency declared and pinned, a hang that
fails its test, a scheduler check that leaves nothing behind, `main` giving back its
signal handler, a quiet local cluster, and benchmark scripts that run."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import tomllib
import warnings
from importlib.metadata import version

import cv2
import numpy as np
import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from bench import ROOT
from bench.cli import main
from bench.frontend.views import exif_focal
from bench.harness.execute import _local_cluster


def pins() -> dict[str, str]:
    lines = (ROOT / "constraints.txt").read_text().splitlines()
    pairs = (line.split("==") for line in lines if line.strip() and not line.startswith("#"))
    return {canonicalize_name(name): v for name, v in pairs}


def test_every_dependency_is_declared_pinned_and_installed_as_pinned():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    declared = [
        Requirement(r) for r in (*project["dependencies"], *extras["test"], *extras["learned"])
    ]
    assert {"pillow", "pytest", "pytest-timeout", "ruff"} <= {
        canonicalize_name(r.name) for r in declared
    }
    pinned = pins()
    for r in declared:
        assert r.specifier.contains(pinned[canonicalize_name(r.name)]), r
    # the environment is the one the pins describe (scripts/setup.sh installs them)
    assert {name: version(name) for name in pinned} == pinned


def test_exif_focal_needs_pillow_and_is_read(tmp_path, monkeypatch):
    from PIL import Image

    path = tmp_path / "exif.jpg"
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = 50  # 35 mm equivalent focal length
    Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(path, exif=exif)
    assert exif_focal(path, 4000, 3000) == pytest.approx(50 / 36 * 4000)
    cv2.imwrite(str(tmp_path / "plain.png"), np.zeros((30, 40, 3), np.uint8))
    assert exif_focal(tmp_path / "plain.png", 4000, 3000) is None
    # without Pillow the prior is not silently the default one
    monkeypatch.setitem(sys.modules, "PIL", None)
    with pytest.raises(ImportError):
        exif_focal(path, 4000, 3000)


def test_a_hanging_test_fails_with_a_stack_dump(tmp_path, pytestconfig):
    assert float(pytestconfig.getini("timeout")) > 0  # every test, by default
    (tmp_path / "test_hang.py").write_text(
        "import threading\n\n\ndef test_deadlock():\n"
        "    lock = threading.Lock()\n    lock.acquire()\n    lock.acquire()\n"
    )
    argv = ["-c", ROOT / "pyproject.toml", "--rootdir", tmp_path, "-o", "timeout=2"]
    out = subprocess.run(
        [sys.executable, "-m", "pytest", *map(str, argv), "-p", "no:cacheprovider", tmp_path],
        capture_output=True,
        text=True,
        timeout=120,
    )
    text = out.stdout + out.stderr
    assert out.returncode != 0 and " Timeout " in text
    assert "in test_deadlock\n    lock.acquire()" in text  # where it hung


# The two refused schedulers of test_run_bad_input_is_one_clear_line, in a row, with the
# garbage collector forced to run where `distributed` starts a client's event loop (holding
# its class lock), then a real client: a half-built client left by a refusal deadlocked the
# next one on that lock when collected there.
FORCED_GC = """
import gc, sys
import distributed.comm
from distributed import Client, LocalCluster
from distributed.utils import LoopRunner
from bench.cli import main

# a refused port is tried again until the connect timeout (10 s): 1 s refuses it the same
real_connect = distributed.comm.connect
distributed.comm.connect = lambda address, timeout: real_connect(address, timeout="1s")

start = LoopRunner._start_unlocked
def collecting(self):
    gc.collect()
    return start(self)
LoopRunner._start_unlocked = collecting

for address in ("notanaddress", "tcp://127.0.0.1:1"):
    print(main(["run", "--scheduler", address, "--results", sys.argv[1]]))
with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
    with Client(cluster) as client:
        print(client.submit(sum, [1, 2]).result())
"""


def test_refused_schedulers_leave_nothing_that_deadlocks_the_next_client(tmp_path):
    try:
        out = subprocess.run(
            [sys.executable, "-c", FORCED_GC, str(tmp_path / "r")],
            capture_output=True,
            text=True,
            timeout=120,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("deadlocked: a refused scheduler left a client behind")
    assert out.stdout.split() == ["2", "2", "3"], out.stderr
    err = out.stderr.strip().splitlines()
    assert len(err) == 2 and all("cannot reach the Dask scheduler" in e for e in err)


def test_main_gives_back_the_sigterm_handler(tmp_path):
    def mine(signum, frame):
        pass

    previous = signal.signal(signal.SIGTERM, mine)
    try:
        assert main(["scenes"]) == 0
        assert signal.getsignal(signal.SIGTERM) is mine
        assert main(["run", "--scheduler", "notanaddress", "--results", str(tmp_path)]) == 2
        assert signal.getsignal(signal.SIGTERM) is mine
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_local_cluster_says_nothing_of_a_port_in_use(capfd):
    with socket.socket() as taken:
        try:
            taken.bind(("", 8787))
            taken.listen()
        except OSError:
            pass  # in use already
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            _local_cluster(0).close()
    said = [str(w.message) for w in caught] + [capfd.readouterr().err]
    assert not [s for s in said if "already in use" in s]


@pytest.mark.parametrize("script", sorted((ROOT / "benchmarks").glob("*.py")), ids=lambda p: p.name)
def test_every_benchmark_script_imports_and_reads_its_arguments(script):
    out = subprocess.run(
        [sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0 and out.stdout.startswith("usage:"), out.stderr
