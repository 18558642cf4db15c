"""`track-first`: tracks from verified matches, and the selection by their length."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bench.backend.matching import PairMatches
from bench.camera import Camera
from bench.frontend.features import Candidates
from bench.frontend.policies import MULTIVIEW, PolicyInput
from bench.frontend.signals import SIGNALS, Signals
from bench.frontend.tracks import NAME, TrackFirstConfig, track_views
from bench.frontend.views import View
from bench.vocabulary import METHODS, MULTI_VIEW


def _pairs(links: dict[tuple[int, int], list[tuple[int, int]]]) -> list[PairMatches]:
    out = []
    for (i, j), m in links.items():
        m = np.array(m, np.int64).reshape(-1, 2)
        out.append(PairMatches(i, j, m, m, "CALIBRATED"))
    return out


def test_track_views_counts_the_distinct_views_of_each_component():
    """v0k0-v1k0-v2k1 spans 3 views; v0k1-v1k1 and v0k2-v2k0 span 2; v0k3 has no match."""
    pairs = _pairs({(0, 1): [(0, 0), (1, 1)], (1, 2): [(0, 1)], (0, 2): [(2, 0)]})
    got = track_views([4, 2, 2], pairs)
    assert [g.tolist() for g in got] == [[3, 2, 2, 0], [3, 2], [2, 3]]


def test_a_component_with_two_keypoints_of_one_view_counts_views_not_keypoints():
    pairs = _pairs({(0, 1): [(0, 0), (1, 0)]})  # two keypoints of view 0 on one of view 1
    assert [g.tolist() for g in track_views([2, 1], pairs)] == [[2, 2], [2]]


def _inputs(n: int = 10, views: int = 3) -> list[PolicyInput]:
    """`views` views of `n` candidates in one tile, texture falling with the index (so a
    per-view score keeps the lowest indices), every other signal 0."""
    cam = Camera(640, 480, 500.0, 500.0, 320.0, 240.0, np.eye(3), np.zeros(3))
    xy = np.c_[np.linspace(5, 50, n), np.linspace(5, 50, n)]
    pool = Candidates(xy, np.ones(n), np.zeros(n), np.ones(n), np.zeros((n, 128), np.float32))
    values = {s: np.zeros(n) for s in SIGNALS} | {"texture": np.linspace(1, 0, n)}
    sig = Signals(**values)
    image = np.zeros((480, 640, 3), np.uint8)
    return [PolicyInput(View(k, f"v{k}", image, cam, posed=False), pool, sig) for k in range(views)]


def test_it_keeps_the_longest_verified_tracks_before_the_score():
    """A 3-view track on candidate 7 and a 2-view track on 8 (views 0 and 1): at B = 2,
    views 0 and 1 keep {7, 8}, view 2 keeps 7 and then its best texture, 0."""
    seen = []

    def match(selections):
        seen.append([s.tolist() for s in selections])
        pos = [{int(c): k for k, c in enumerate(s)} for s in selections]
        links = {
            (0, 1): [(pos[0][7], pos[1][7]), (pos[0][8], pos[1][8])],
            (1, 2): [(pos[1][7], pos[2][7])],
        }
        return _pairs(links)

    cfg = TrackFirstConfig(first_pass=5)
    sel, rounds = MULTIVIEW[NAME](_inputs(), 2, cfg, match)
    assert [s.tolist() for s in sel] == [[7, 8], [7, 8], [0, 7]]
    assert rounds == [] and seen == [[list(range(10))] * 3]  # one first pass of 5 B


def test_without_any_verified_match_it_is_the_cross_view_selection():
    sel, _ = MULTIVIEW[NAME](_inputs(), 3, TrackFirstConfig(), lambda s: [])
    assert [s.tolist() for s in sel] == [[0, 1, 2]] * 3


def test_it_is_declared_a_multi_view_policy_reading_cross_views_signals():
    m = METHODS[NAME]
    assert m.kind == MULTI_VIEW and "epipolar" in m.reads and m.role == "contender"


def test_track_lengths_go_to_the_first_passs_candidates_by_id_not_by_position():
    """Texture rising with the index: a first pass of 2 B = 2 holds candidates 8 and 9 of
    10 (positions 0 and 1); a 3-view track on candidate 8 makes B = 1 keep 8, not 0 (the
    candidate at 8's position) and not 9 (the best score)."""
    inputs = _inputs()
    inputs = [replace(i, signals=replace(i.signals, texture=np.linspace(0, 1, 10))) for i in inputs]
    seen = []

    def match(selections):
        seen.append([s.tolist() for s in selections])
        return _pairs({(0, 1): [(0, 0)], (1, 2): [(0, 0)]})

    sel, _ = MULTIVIEW[NAME](inputs, 1, TrackFirstConfig(first_pass=2), match)
    assert seen == [[[8, 9]] * 3] and [s.tolist() for s in sel] == [[8]] * 3
