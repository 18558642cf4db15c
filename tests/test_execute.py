"""Execution: on Dask workers as in one process, retries, signals; the command line's options
and settings as the README lists them."""

from __future__ import annotations

import dataclasses
import math
import os
import shutil

import pandas as pd
import pytest

from bench import vocabulary
from bench.cli import build_parser, main
from bench.frontend import plugins
from bench.frontend import policies as registry
from bench.frontend.policies import PolicyConfig
from bench.harness import execute
from bench.harness.grid import BenchConfig, in_grid
from bench.report import figures
from bench.report.write import write_report
from bench.runs import read_runs
from bench.unit.config import RunConfig
from bench.vocabulary import KEY, Vocabulary
from tests.conftest import (
    MEDIUM,
    TIMING,
    bench_run,
    default_sigint,
    small_grid,
    spy,
)

SMALL = small_grid()


# --- execution on Dask (issue 14) --------------------------------------------------------

PARALLEL = dataclasses.replace(
    SMALL, scenes=("table",), methods=("texture", "adaptive", "oracle", "colmap-b")
)


def test_two_dask_workers_give_the_same_metrics_as_one_process(
    quick_results, renders_dir, tmp_path
):
    # one process: these units' rows of the small grid, which the session ran in one
    one = in_grid(PARALLEL, read_runs(quick_results / "runs.csv"))
    assert len(one) == 3 * 5 + 3  # the three selections' jobs and colmap-b's
    two = bench_run(PARALLEL, tmp_path / "two", renders_dir, workers=2)
    # reference_maps is no value of a row: readers add it from the grid's stock COLMAP rows
    metrics = [c for c in one.columns if c not in [*TIMING, "reference_maps"]]
    pd.testing.assert_frame_equal(
        one[metrics].sort_values(list(KEY), ignore_index=True),
        two[metrics].sort_values(list(KEY), ignore_index=True),
    )


def test_a_unit_failing_on_a_worker_is_retried_once_then_recorded(
    renders_dir, tmp_path, monkeypatch
):
    from distributed import LocalCluster

    calls = []
    real = execute.predict

    def flaky(scene, unit, *a):
        calls.append(unit.method)
        if unit.method == "texture":
            raise RuntimeError("worker lost")
        return real(scene, unit, *a)

    monkeypatch.setattr(execute, "predict", flaky)
    two = dataclasses.replace(PARALLEL, methods=("texture", "oracle"))  # a failing, a good one
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        bench_run(two, tmp_path, renders_dir, scheduler=cluster.scheduler_address)
    assert calls.count("texture") == 2  # tried, then retried once
    runs = read_runs(tmp_path / "runs.csv")
    failed = runs[runs["method"] == "texture"]
    assert len(failed) == 5 and (failed["status"] == "failed").all()
    assert failed["failure"].str.contains("retried once: RuntimeError: worker lost").all()
    assert (runs.loc[runs["method"] != "texture", "status"] == "ok").any()


def test_a_raising_policy_on_workers_is_one_line_without_retry_or_traceback(
    renders_dir, tmp_path, capfd
):
    module = tmp_path / "boom.py"
    calls = tmp_path / "calls.txt"
    module.write_text(
        "from bench.frontend.policies import policy\n\n"
        "@policy('boom')\n"
        "def boom(inp, budget, rng, cfg):\n"
        f"    open({str(calls)!r}, 'a').write('call\\n')\n"
        "    raise ValueError('deterministic')\n"
    )
    argv = ["run", "--quick", "--scenes", "table", "--methods", "boom", "--workers", "2"]
    argv += ["--policy-module", str(module), "--tasks", "tri", "--protocols", "multiview"]
    # the session's renders: the --quick table, which the signal tests below read too
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(renders_dir)]) == 2
    err = capfd.readouterr().err
    assert "policy boom failed: ValueError: deterministic" in err and "Traceback" not in err
    assert len(calls.read_text().splitlines()) == 1  # the first view raised; no retry


@pytest.mark.parametrize(
    "sig, code, said", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")]
)
def test_a_signal_to_the_process_group_with_workers_stops_in_a_few_lines(
    renders_dir, tmp_path, sig, code, said
):
    """Ctrl-C (a terminal) and SIGTERM (`timeout`, systemd) reach the whole process group,
    workers included. SIGTERM printed each worker's native stack (glog's failure handler,
    which pycolmap installs: 62 lines, two dumps interleaved); now one line, as Ctrl-C."""
    import signal
    import subprocess
    import sys
    import time

    cmd = [sys.executable, "-m", "bench", "run", "--quick", "--scenes", "table", "--workers", "2"]
    cmd += ["--results", str(tmp_path / "r"), "--renders", str(renders_dir)]
    proc = subprocess.Popen(
        cmd, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=default_sigint
    )
    deadline = time.monotonic() + 120
    while not (tmp_path / "r" / "runs.csv").exists() and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.1)
    os.killpg(proc.pid, getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    lines = err.strip().splitlines()
    assert proc.returncode == code, err
    assert lines[-1] == f"bench: {said}; finished work is kept", err
    assert all(line.startswith("bench: ") for line in lines), err  # no stack, no warning
    assert len(read_runs(tmp_path / "r" / "runs.csv")) >= 1  # the rows computed are kept


STARTING = """
import os, signal, sys
from distributed import nanny
from bench.cli import Terminated, _terminate
from bench.harness import execute

start = nanny.Nanny.start_unsafe

async def signalled(self):  # as `timeout` sends it, while the workers start
    os.kill(os.getpid(), signal.SIGTERM)
    return await start(self)

nanny.Nanny.start_unsafe = signalled
signal.signal(signal.SIGTERM, _terminate)
plan = execute.Plan({}, {})
try:
    list(execute._on_dask(plan, None, None, execute.Cluster(workers=2), None))
except Terminated:
    print("terminated", file=sys.stderr)
    sys.exit(143)
"""


def test_a_sigterm_while_the_local_cluster_starts_ends_in_one_line():
    """Stopped half-started, distributed's exit hook failed on the workers still starting
    (`AssertionError: Status.init`, a traceback after the last line); now the start ends,
    the cluster is closed, and the SIGTERM is acted on."""
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-c", STARTING], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 143, proc.stderr
    assert proc.stderr.strip() == "terminated", proc.stderr


def test_the_readme_synopsis_names_every_option_of_every_command():
    import argparse
    import re

    from bench import ROOT

    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index("bench scenes  ") :]
    block = block[: block.index("```")]
    synopsis: dict[str, str] = {}
    for line in block.splitlines():
        if line.startswith("bench "):
            command = line.split()[1]
        synopsis[command] = synopsis.get(command, "") + line
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(synopsis)
    for command, parser in sub.choices.items():
        options = {o for a in parser._actions for o in a.option_strings if o.startswith("--")}
        missing = options - {"--help"} - set(re.findall(r"--[a-z-]+", synopsis[command]))
        assert not missing, f"bench {command}: {sorted(missing)} not in the README synopsis"


def test_a_results_folder_that_cannot_be_written_is_one_line(tmp_path, capsys):
    (tmp_path / "file").write_text("not a folder")
    argv = ["run", "--quick", "--scenes", "table", "--results", str(tmp_path / "file" / "r")]
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1
    assert f"{tmp_path / 'file'} in {tmp_path / 'file' / 'r'} is a file; give a folder" in err[0]


def test_images_without_any_candidate_are_named_not_a_budget_of_0(tmp_path, capsys):
    argv = ["run", "--scenes", "table", "--seeds", "0", "--width", "8", "--height", "6"]
    argv += ["--spp", "1", "--denoise", "0", "--budget", "1", "--workers", "1"]
    argv += ["--renders", str(tmp_path)]
    assert main([*argv, "--results", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "found no candidate in any view of table seed 0" in err and "up to 0" not in err


def test_a_twoview_only_run_prints_its_table_and_sfm_only_rows_name_figure2s_task(
    quick_results, tmp_path, renders_dir, capsys
):
    argv = ["run", "--scenes", "table", "--seeds", "0", "--budget", "64", "--workers", "1"]
    argv += ["--methods", "texture", "--protocols", "twoview", "--width", "320"]
    argv += ["--height", "240", "--spp", "16", "--max-depth", "2"]
    assert main([*argv, "--results", str(tmp_path / "r"), "--renders", str(renders_dir)]) == 0
    out = capsys.readouterr().out
    assert "Table 1 (twoview protocol" in out and "Empty DataFrame" not in out
    runs = read_runs(quick_results / "runs.csv")
    (tmp_path / "s").mkdir()
    shutil.copy(quick_results / "vocabulary.json", tmp_path / "s")
    write_report(runs[runs["task"] == "sfm"], tmp_path / "s", renders_dir)
    err = capsys.readouterr().err
    assert "figure2.png not drawn" in err and "points of the tri task of adaptive on table" in err


def test_the_budget_figure_says_n_a_for_a_panel_without_values(monkeypatch, tmp_path):
    from bench.report.tables import table1

    t1 = table1(
        pd.DataFrame(
            {
                "scene": "table",
                "seed": 0,
                "method": "texture",
                "budget": [64, 128],
                "status": "ok",
                "acc_completeness_pct": [1.0, 2.0],
                "completeness_vs_oracle_pct": math.nan,  # no oracle ran
            }
        ),
        Vocabulary.current(),
    )
    drawn = {}
    monkeypatch.setattr(figures, "save", lambda fig, out, fmts: drawn.update(fig=fig))
    figures.figure_budget(t1, Vocabulary.current(), tmp_path / "figure_budget")
    texts = {
        ax.get_title(): [t.get_text() for t in ax.texts]
        for ax in drawn["fig"].axes
        if ax.get_visible()
    }
    oracle = next(k for k in texts if "oracle" in k)
    assert texts[oracle] == ["n/a: no run has this value"]
    assert all(not v for k, v in texts.items() if k != oracle)


def test_a_policy_module_decides_its_own_rows_only(renders_dir, tmp_path, monkeypatch):
    """A module's path is not bound into the folder (running without it is not refused),
    and editing it recomputes its policy's rows alone, not the built-in policies'."""
    module = tmp_path / "mine.py"
    source = (
        "import numpy as np\nfrom bench.frontend.policies import policy\n\n"
        "@policy('mine-{v}')\ndef mine(inp, budget, rng, cfg):\n"
        "    return np.arange(min(budget, len(inp.candidates)))\n"
    )
    module.write_text(source.format(v=1))
    grid = dict(scenes=("table",), seeds=(0,), budgets=(64,), tasks=("tri",))
    grid |= dict(protocols=("multiview",))

    def cfg(policies, modules=()):
        run = RunConfig(render=MEDIUM, policy=dataclasses.replace(PolicyConfig(), modules=modules))
        return BenchConfig(methods=policies, run=run, **grid)

    calls = []
    spy(monkeypatch, calls, lambda unit: unit.method)
    results = tmp_path / "r"
    bench_run(cfg(("texture", "mine-1"), (str(module),)), results, renders_dir)
    assert sorted(calls) == ["mine-1", "texture"]
    calls.clear()
    bench_run(cfg(("texture",)), results, renders_dir)  # without the module: not refused
    assert calls == [] and set(read_runs(results / "runs.csv")["method"]) == {"texture", "mine-1"}
    module.write_text(source.format(v=1).replace("np.arange(", "1 + np.arange("))
    plugins.load_module.cache_clear()
    registry.POLICIES.pop("mine-1")
    vocabulary.METHODS.pop("mine-1")
    bench_run(cfg(("texture", "mine-1"), (str(module),)), results, renders_dir)
    assert calls == ["mine-1"]  # the edited module's rows alone
