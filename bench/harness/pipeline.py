"""One benchmark run, end to end: (render entry, policy, budget) -> one row of metrics.

render entry -> front end (cached) -> policy selects B per view -> match -> verify ->
triangulate (COLMAP, known poses) -> export the model -> evaluate against ground truth.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bench.backend.matching import BackendConfig
from bench.backend.reconstruction import known_pose_model, reconstruct
from bench.evaluation.metrics import SceneTruth, evaluate
from bench.files import content_key
from bench.frontend.features import DetectorConfig
from bench.frontend.policies import SIGNALS_USED, PolicyConfig, PolicyInput, select
from bench.frontend.signals import SignalConfig
from bench.frontend.stage import FrontEnd
from bench.render.config import RenderConfig


@dataclass(frozen=True)
class RunConfig:
    """Everything that decides a run's metrics (its hash is stored in every row)."""

    render: RenderConfig = field(default_factory=RenderConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    signals: SignalConfig = field(default_factory=SignalConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def hash(self) -> str:
        return content_key(self.as_dict())


def policy_rng(seed: int, policy: str, budget: int, view: int) -> np.random.Generator:
    """The generator of one unit of work, derived from the run's seed."""
    return np.random.default_rng([seed, zlib.crc32(policy.encode()), budget, view])


def select_features(
    fe: FrontEnd, policy: str, budget: int, seed: int, cfg: PolicyConfig
) -> tuple[list[np.ndarray], float]:
    t = time.perf_counter()
    sel = [
        select(policy, PolicyInput(v, c, s), budget, policy_rng(seed, policy, budget, v.index), cfg)
        for v, c, s in zip(fe.views, fe.pools, fe.signals)
    ]
    return sel, time.perf_counter() - t


def export_model(model, out: Path) -> None:
    """COLMAP text model + points.ply, written to a temporary directory then renamed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".tmp-{out.name}-", dir=out.parent))
    try:
        model.write_text(str(tmp))
        model.export_PLY(str(tmp / "points.ply"))
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def run_one(
    entry: Path,
    fe: FrontEnd,
    truth: SceneTruth,
    scene: str,
    seed: int,
    policy: str,
    budget: int,
    cfg: RunConfig,
    model_dir: Path,
) -> dict:
    """One row: identification, every metric, stage timings (ms), and a failure reason if any."""
    row: dict = {
        "scene": scene,
        "seed": seed,
        "policy": policy,
        "budget": budget,
        "render_key": Path(entry).name,
        "config_hash": cfg.hash,
    }
    selections, select_s = select_features(fe, policy, budget, seed, cfg.policy)
    cams = [v.camera for v in fe.views]
    xy = [c.xy[s] for c, s in zip(fe.pools, selections)]
    desc = [c.descriptors[s] for c, s in zip(fe.pools, selections)]
    rec = reconstruct(entry, cams, xy, desc, cfg.backend)
    export_model(
        rec.model
        if rec.model is not None
        else known_pose_model(cams, [f"view_{k:02d}.png" for k in range(len(cams))], xy),
        model_dir,
    )
    t = time.perf_counter()
    row |= evaluate(truth, fe.pools, selections, rec, len(SIGNALS_USED[policy]))
    seconds = {
        "detect": fe.seconds["detect"],
        "signals": sum(fe.seconds[s] for s in SIGNALS_USED[policy]),
        "select": select_s,
        "match": rec.seconds.get("match", 0.0),
        "verify": rec.seconds.get("verify", 0.0),
        "triangulate": rec.seconds.get("triangulate", 0.0),
        "evaluate": time.perf_counter() - t,
    }
    meta = json.loads((Path(entry) / "meta.json").read_text())
    row["render_s_per_view"] = float(np.mean(meta["seconds_per_view"]))
    row |= {f"{k}_ms": 1000 * v for k, v in seconds.items()}
    row["wall_ms"] = 1000 * sum(v for k, v in seconds.items() if k != "evaluate")
    row["status"] = "ok" if rec.failure is None else "failed"
    row["failure"] = rec.failure or ""
    if rec.failure:
        for k in ("rmse", "median_error"):
            row[k] = math.nan
    return row
