"""The order units are submitted in (`bench.harness.execute.largest_first`): scene by
scene as the plan holds them, the costliest of each scene first."""

from __future__ import annotations

from pathlib import Path

from bench.harness.execute import Plan, Work, largest_first
from bench.vocabulary import Job, Unit

JOBS = (Job("tri", "multiview"), Job("tri", "twoview"))


def test_units_go_scene_by_scene_whole_pool_and_pipelines_first_then_by_budget():
    entries = {("table", 0): Path("t"), ("facade", 0): Path("f")}
    units = [
        Unit(sc, 0, m, b)
        for sc in ("facade", "table")
        for m, b in [
            ("random", 128),
            ("random", 512),
            ("all", 0),
            ("oracle", 128),
            ("colmap-b", 128),
        ]
    ]
    work = {u: Work(JOBS) for u in units}
    work[Unit("table", 0, "adaptive-loop", 256)] = Work(JOBS)
    work[Unit("table", 0, "grid", 512)] = Work(JOBS[:1])
    order = [(u.scene, u.method, u.budget) for u in largest_first(Plan(entries, work))]
    table = [
        ("table", "all", 0),
        ("table", "oracle", 128),  # a tie: in the plan's order
        ("table", "colmap-b", 128),
        ("table", "adaptive-loop", 256),
        ("table", "random", 512),
        ("table", "grid", 512),
        ("table", "random", 128),
    ]
    assert order[: len(table)] == table
    assert [s for s, _, _ in order[len(table) :]] == ["facade"] * 5
    assert order[len(table) :][:2] == [("facade", "all", 0), ("facade", "oracle", 128)]
