"""The field's selectors, the feedback loop, learned weights and policies from outside."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench import ROOT, BenchError
from bench.backend.matching import BackendConfig, match_and_verify
from bench.frontend import feedback, plugins
from bench.frontend.features import DetectorConfig
from bench.frontend.geometry import SignalConfig, depth_priors
from bench.frontend.policies import (
    POLICIES,
    SHIPPED_WEIGHTS,
    PolicyInput,
    contract_violation,
    policy,
    select,
    tile_of,
)
from bench.frontend.stage import front_end
from bench.harness.grid import BenchConfig
from bench.vocabulary import METHODS, MULTI_VIEW, PER_VIEW

BUDGET = 64


@pytest.fixture(scope="module")
def fe(medium_entry, frontend_cache):
    return front_end(medium_entry("table"), DetectorConfig(), SignalConfig(), frontend_cache)


def _inputs(fe):
    return [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]


def _tiles_used(inp, idx, tiles=(8, 6)):
    cam = inp.view.camera
    return len(set(tile_of(inp.candidates.xy[idx], cam.width, cam.height, tiles)))


@pytest.mark.parametrize("name", ["ssc", "quadtree"])
def test_spreading_selectors_cover_more_of_the_image_than_top_response(fe, name):
    for inp in _inputs(fe):
        spread = select(name, inp, BUDGET, np.random.default_rng(0))
        top = select("response", inp, BUDGET, np.random.default_rng(0))
        assert _tiles_used(inp, spread) > _tiles_used(inp, top)


def test_response_takes_the_strongest(fe):
    inp = _inputs(fe)[0]
    idx = select("response", inp, BUDGET, np.random.default_rng(0))
    r = inp.candidates.response
    assert r[idx].min() >= np.sort(r)[-BUDGET]


def test_scale_takes_the_largest_and_keeps_larger_scales_than_response(fe):
    """COLMAP's cap order on the pool (issue 53): the B largest scales, at least as large
    as response's B (which on the renders keep the finest extrema)."""
    for inp in _inputs(fe):
        idx = select("scale", inp, BUDGET, np.random.default_rng(0))
        top = select("response", inp, BUDGET, np.random.default_rng(0))
        size = inp.candidates.size
        assert size[idx].min() >= np.sort(size)[-BUDGET]
        assert np.median(size[idx]) >= np.median(size[top])


def test_scale_breaks_ties_of_size_by_response(fe):
    """A pool of equal sizes (as ORB's are): `scale` keeps the strongest responses, not the
    first indices."""
    from dataclasses import replace

    inp = _inputs(fe)[0]
    same = replace(inp.candidates, size=np.full(len(inp.candidates.size), 7.0, np.float32))
    idx = select("scale", replace(inp, candidates=same), BUDGET, np.random.default_rng(0))
    r = same.response
    assert r[idx].min() >= np.sort(r)[-BUDGET] and not np.array_equal(idx, np.arange(BUDGET))


def test_peak_scale_takes_the_largest_scales_above_colmaps_peak_threshold_first(fe):
    from bench.frontend.policies import PEAK_THRESHOLD

    for inp in _inputs(fe):
        idx = select("peak-scale", inp, BUDGET, np.random.default_rng(0))
        c = inp.candidates
        strong = c.response >= PEAK_THRESHOLD
        assert len(idx) == len(set(idx)) == BUDGET and strong.sum() > BUDGET
        assert strong[idx].all()  # none faint while the strong ones last
        assert c.size[idx].min() >= np.sort(c.size[strong])[-BUDGET]
        assert (
            c.response[select("scale", inp, BUDGET, np.random.default_rng(0))] < PEAK_THRESHOLD
        ).any()


def test_octave_scale_keeps_none_coarser_than_colmaps_octaves_while_others_last(fe):
    """`peak-scale` kept 4-11 extrema per view coarser than any COLMAP's SIFT extracts;
    `octave-scale` keeps the largest strong ones within COLMAP's octaves first."""
    from bench.frontend.policies import COLMAP_MAX_SIGMA, PEAK_THRESHOLD

    assert 16.1 < COLMAP_MAX_SIGMA < 16.2
    coarse = [(i.candidates.size / 2 > COLMAP_MAX_SIGMA).sum() for i in _inputs(fe)]
    assert sum(coarse) > 0  # the pool holds what the policy puts last
    for inp in _inputs(fe):
        c = inp.candidates
        first = (c.response >= PEAK_THRESHOLD) & (c.size / 2 <= COLMAP_MAX_SIGMA)
        for budget in (BUDGET, int(first.sum()) + 3):
            idx = select("octave-scale", inp, budget, np.random.default_rng(0))
            assert len(idx) == len(set(idx)) == min(budget, len(c))
            if budget <= first.sum():
                assert first[idx].all() and c.size[idx].min() >= np.sort(c.size[first])[-budget]
            else:
                assert first[idx].sum() == first.sum()  # all of them, then the others
        assert np.array_equal(idx, select("octave-scale", inp, budget, np.random.default_rng(1)))


def test_feedback_loop_meets_the_budget_logs_rounds_and_is_deterministic(fe):
    cams = [v.camera for v in fe.views]

    def match(sel):
        xy = [c.xy[s] for c, s in zip(fe.pools, sel)]
        return match_and_verify(
            cams, xy, [c.descriptors[s] for c, s in zip(fe.pools, sel)], BackendConfig(), "sift"
        )[0]

    cfg = feedback.LoopConfig(loop_rounds=2)
    sel, rounds = feedback.feedback_select(_inputs(fe), BUDGET, cfg, match)
    again, _ = feedback.feedback_select(_inputs(fe), BUDGET, cfg, match)
    assert all(np.array_equal(a, b) for a, b in zip(sel, again))
    for s, c in zip(sel, fe.pools):
        assert len(s) == BUDGET == len(set(s.tolist())) and s.max() < len(c)
    assert [r["round"] for r in rounds] == [0, 1]
    view = rounds[0]["views"][0]
    assert len(view["quota"]) == 48 and view["kept"] + sum(view["quota"]) <= BUDGET
    first = [select("adaptive", i, BUDGET, np.random.default_rng(0)) for i in _inputs(fe)]
    assert any(not np.array_equal(np.sort(a), np.sort(b)) for a, b in zip(first, sel))


def test_learned_weights_are_shipped_with_provenance_and_disjoint_seeds():
    data = json.loads(SHIPPED_WEIGHTS.read_text())
    assert {"weights", "seeds", "scenes", "code", "samples"} <= set(data)
    assert not set(data["seeds"]) & set(BenchConfig().seeds)  # never evaluated on its seeds
    BenchConfig(scenes=("table",)).validate()
    with pytest.raises(BenchError, match="trained on seed"):
        BenchConfig(scenes=("table",), seeds=(0, data["seeds"][0])).validate()


def test_depth_prior_from_the_data_matches_the_rendered_depth(fe, medium_entry):
    from bench.evaluation.layers import read_layers

    depths = depth_priors(fe.views, fe.pools, SignalConfig())
    for d, gt, c in zip(depths, read_layers(medium_entry("table")), fe.pools):
        col, row = (c.xy - 0.5).round().astype(int).T
        true = np.nanmedian(gt.z[row.clip(0, 239), col.clip(0, 319)])  # under the candidates
        assert 0.8 * true < d < 1.25 * true


@pytest.mark.parametrize(
    "idx, want, n, broken",
    [
        ([0, 1, 2], 3, 3, None),
        ([2, 0, 1], 3, 4, None),
        ([0, 1, 3], 3, 3, "valid range: indices must lie in [0, 3), got 0..3"),  # index n
        ([-1, 0, 1], 3, 3, "valid range: indices must lie in [0, 3), got -1..1"),
        ([0, 0, 1], 3, 3, "distinct indices: 1 repeated"),
        ([0, 1], 3, 3, "exact budget: 2 indices returned, 3 expected"),
        ([], 0, 0, None),
    ],
)
def test_the_contract_rules_on_hand_made_selections(idx, want, n, broken):
    assert contract_violation(np.array(idx, dtype=int), want, n) == broken


def test_a_policy_module_registers_and_its_broken_rules_are_named(fe, tmp_path):
    added = plugins.load_module(str(ROOT / "examples" / "my_policy.py"))
    assert added == ("center-texture",)
    inp = _inputs(fe)[0]
    assert len(select("center-texture", inp, BUDGET, np.random.default_rng(0))) == BUDGET
    short = tmp_path / "short.py"
    short.write_text(
        "from bench.frontend.policies import policy\n"
        "@policy('short')\n"
        "def short(inp, budget, rng, cfg):\n"
        "    return list(range(budget - 1)) + [0]\n"
    )
    plugins.load_module(str(short))
    with pytest.raises(BenchError, match="'distinct indices"):
        select("short", inp, BUDGET, np.random.default_rng(0))
    with pytest.raises(BenchError, match="'exact budget"):
        policy("short2")(lambda inp, b, rng, cfg: np.arange(b - 1))
        try:
            select("short2", inp, BUDGET, np.random.default_rng(0))
        finally:
            del POLICIES["short2"], METHODS["short2"]
    peek = tmp_path / "peek.py"
    peek.write_text(
        "from bench.evaluation.layers import read_layers\n"
        "from bench.frontend.policies import policy\n"
    )
    with pytest.raises(BenchError, match="'no ground truth': it imports bench.evaluation"):
        plugins.load_module(str(peek))
    files = tmp_path / "files.py"
    files.write_text("PATH = 'renders/x/gt_00.npz'\n")
    with pytest.raises(BenchError, match="'no ground truth': it names ground truth"):
        plugins.load_module(str(files))


@pytest.mark.parametrize(
    "source, message",
    [
        ("def broken(:\n", r"is not valid Python: invalid syntax \(line 1\)|is not valid Python"),
        (
            "@policy('texture')\ndef mine(inp, budget, rng, cfg):\n    return []\n",
            "policy name 'texture' is taken",
        ),
        (
            "@policy('typo', reads=('texure',))\ndef typo(inp, budget, rng, cfg):\n    return []\n",
            "reads unknown signal 'texure'; valid: texture,",
        ),
    ],
)
def test_a_policy_modules_mistakes_are_named(tmp_path, source, message):
    module = tmp_path / "mine.py"
    module.write_text("from bench.frontend.policies import policy\n" + source)
    with pytest.raises(BenchError, match=message) as e:
        plugins.load_module(str(module))
    assert "no ground truth" not in str(e.value) and "registers no new policy" not in str(e.value)


def test_sys_exit_in_a_policy_is_a_failure_named_not_an_exit(fe, tmp_path):
    module = tmp_path / "leaves.py"
    module.write_text(
        "import sys\nfrom bench.frontend.policies import policy\n\n"
        "@policy('leaves')\ndef leaves(inp, budget, rng, cfg):\n    sys.exit(3)\n"
    )
    plugins.load_module(str(module))
    try:
        with pytest.raises(BenchError, match="policy leaves failed: SystemExit: 3"):
            select("leaves", _inputs(fe)[0], BUDGET, np.random.default_rng(0))
    finally:
        POLICIES.pop("leaves")


def test_an_installed_entry_point_registers_its_policies(monkeypatch):
    from importlib.metadata import EntryPoint

    ep = EntryPoint(name="first", value="tests.plugin_policy", group=plugins.ENTRY_POINT_GROUP)
    monkeypatch.setattr(plugins, "entry_points", lambda group: [ep] if group == ep.group else [])
    try:
        assert plugins.load_entry_points.__wrapped__() == ("first-b",)
    finally:
        POLICIES.pop("first-b", None)


def _dataset(entry, out, rng=None):
    """A dataset folder of a render entry's images and rig, with random poses if `rng`."""
    import shutil

    from scipy.spatial.transform import Rotation

    from bench.camera import Camera, write_colmap_rig
    from bench.frontend.views import load_views

    views = load_views(entry)
    (out / "images").mkdir(parents=True)
    (out / "sparse").mkdir()
    for v in views:
        shutil.copy(entry / v.name, out / "images" / v.name)
    cams = [v.camera for v in views]
    if rng is not None:
        cams = [
            Camera(c.width, c.height, c.fx, c.fy, c.cx, c.cy, R, rng.normal(0, 5, 3))
            for c, R in zip(cams, Rotation.random(len(cams), rng).as_matrix())
        ]
    write_colmap_rig(cams, out / "sparse", [v.name for v in views])
    return out


def test_sfm_selections_are_blind_to_the_poses_and_tri_selections_are_not(medium_entry, tmp_path):
    """Every policy's sfm selection is array-equal with the rig's poses replaced by random
    ones (the task grants no poses: `GRANTS`); cross-view's tri selection, which reads the
    epipolar geometry of the poses, changes."""
    from bench.backend.matching import matcher
    from bench.frontend.policies import PolicyInput
    from bench.frontend.selection import select_views
    from bench.harness.grid import default_methods
    from bench.unit.config import RunConfig
    from bench.unit.tasks import TASK_RUNNERS

    entry = medium_entry("table")
    true = _dataset(entry, tmp_path / "true")
    wrong = _dataset(entry, tmp_path / "random", np.random.default_rng(0))
    cfg = RunConfig()

    def selections(dataset, task, policy):
        grant = TASK_RUNNERS[task].spec.grant
        fe = front_end(dataset, cfg.detector, cfg.signals, tmp_path / "fe", grant)
        inputs = [PolicyInput(v, c, s) for v, c, s in zip(fe.views, fe.pools, fe.signals)]
        match = matcher([v.camera for v in fe.views], fe.pools, cfg.backend, "sift")
        return select_views(policy, inputs, BUDGET, 0, cfg.policy, match)[0]

    roles = ("baseline", "contender")
    selecting = (PER_VIEW, MULTI_VIEW)  # the view choosers are baselines too, of views
    for name in [
        p for p in default_methods() if METHODS[p].role in roles and METHODS[p].kind in selecting
    ]:
        a, b = selections(true, "sfm", name), selections(wrong, "sfm", name)
        assert all(np.array_equal(x, y) for x, y in zip(a, b)), name
    a, b = selections(true, "tri", "cross-view"), selections(wrong, "tri", "cross-view")
    assert not all(np.array_equal(x, y) for x, y in zip(a, b))


def test_feedback_diagnostics_of_pairs_verified_with_and_without_a_pose():
    """Unposed views (the sfm task): a pair verified without a relative pose (COLMAP's
    planar or panoramic cases) has tracks of unknown angle, 0, instead of an error; with a
    pose of 10 degrees about y the rays of one direction meet at 10 degrees."""
    from bench.backend.matching import PairMatches
    from bench.camera import Camera
    from bench.frontend.features import Candidates
    from bench.frontend.views import View

    cam = Camera(64, 48, 50.0, 50.0, 32.0, 24.0, np.eye(3), np.zeros(3))  # identity pose
    xy = np.array([[32.0, 24.0], [10.5, 10.5], [50.5, 40.5]])
    pool = Candidates(xy, np.ones(3), np.zeros(3), np.ones(3), np.eye(3, 128, dtype=np.float32))
    image = np.zeros((48, 64, 3), np.uint8)
    inputs = [PolicyInput(View(k, f"v{k}", image, cam, posed=False), pool, None) for k in (0, 1)]
    sel, m = [np.arange(3)] * 2, np.array([[0, 0], [1, 1], [2, 2]])
    no_pose = feedback.keypoint_diagnostics(inputs, sel, [PairMatches(0, 1, m, m, "PLANAR")])
    assert no_pose[0]["verified"].all() and (no_pose[0]["track_views"] == 2).all()
    assert (no_pose[0]["track_angle"] == 0).all()
    c, s = np.cos(np.radians(10)), np.sin(np.radians(10))
    pose = np.c_[np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), [1.0, 0, 0]]
    posed = feedback.keypoint_diagnostics(
        inputs, sel, [PairMatches(0, 1, m, m, "CALIBRATED", pose)]
    )
    assert posed[0]["track_angle"][0] == pytest.approx(10.0, abs=1e-6)
