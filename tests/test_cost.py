"""The cost figure's frontiers (issue 63): each category's stock-COLMAP peer runs alone at
the frontier budgets, whose rows enter the cost table and figure and nothing else."""

from __future__ import annotations

import pandas as pd

from bench.harness.execute import Plan, Work
from bench.harness.grid import BenchConfig
from bench.report.cost import frontier_only
from bench.unit.config import RunConfig
from bench.vocabulary import FRONTIER_PEERS, Unit


def test_the_frontier_peers_alone_run_at_the_frontier_budgets():
    cfg = BenchConfig(
        scenes=("facade",),
        seeds=(0,),
        methods=("grid", "all", *FRONTIER_PEERS),
        budgets=(128, 256),
        frontier=(256, 1024, 2048),
    )
    budgets = {}
    for u in cfg.units():
        budgets.setdefault(u.method, []).append(u.budget)
    assert budgets["grid"] == [128, 256] and budgets["all"] == [0]
    for peer in FRONTIER_PEERS:
        assert budgets[peer] == [128, 256, 1024, 2048]
    assert {u.budget for u in BenchConfig(methods=FRONTIER_PEERS, scenes=("facade",)).units()} == {
        128,
        256,
        512,
    }


def test_a_peers_budget_is_not_checked_against_the_front_ends_pools():
    # a peer extracts its own pool, so 2048 may exceed every candidate pool of the harness
    work = {Unit("facade", 0, m, b): Work(()) for m, b in (("grid", 256), ("colmap-b", 2048))}
    work |= {Unit("facade", 0, "colmap-tracks-b", 1024): Work(())}
    run = RunConfig()
    assert Plan({}, work).budgets(run) == {run.detector: (256,)}


def test_the_frontier_rows_are_the_cost_figures_alone():
    rows = [("grid", 256), ("colmap-b", 256), ("colmap-b", 1024), ("colmap-tracks-b", 2048)]
    rows += [("all", 0), ("colmap-soft-b", 1024)]
    df = pd.DataFrame(rows, columns=["method", "budget"])
    assert frontier_only(df).tolist() == [False, False, False, True, False, False]
