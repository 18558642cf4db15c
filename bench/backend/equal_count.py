"""Equal keypoints: a budgeted policy run at a peer's own keypoint count in each view.

COLMAP's soft limit (`colmap-soft-b`) keeps whole scale levels until SIFT's maximum number
of features is reached, so at budget B a view holds up to about twice B keypoints (its
rows' `keypoints_per_view`). A comparison at budget B then compares unequal counts. The
method `<policy>@<peer>` (kind `EQUAL_COUNT`, e.g. `cross-view@colmap-soft-b`) runs the
per-view policy at budget B with, in view v, exactly the number of keypoints the peer
holds there at budget B (all of the view's pool where it holds fewer): the same count
per view, not an interpolation of the budget curve (which would be a model).

The peer's count per view is its own extraction at budget B (`peer_counts`: the peer's
cached extraction, `bench.backend.peers.peer_extraction`, on the same images, one thread, so
deterministic and equal to what the peer's unit holds), read by the unit itself: units stay
independent of each other (none waits for another's stored prediction), and the one-way flow holds (images
-> counts -> selection). The peer reads the images only, so the method sees no more
than the sfm task grants. It selects (`bench.frontend.selection.select_views` with a
budget per view), matches and is scored like its policy (`bench.unit.equal`); its own
settings are its policy's, set under its own name
(`--set cross-view@colmap-soft-b.epipolar_weight=...`). Its rows run the tasks the
peers run (role `peer`: sfm and pairs) and the report compares them with the peer
(`table1_equal.csv`, `bench.report.tables.equal_keypoints`).
"""

from __future__ import annotations

from pathlib import Path

from bench.backend.peers import peer_extraction
from bench.camera import Camera
from bench.frontend.tracks import NAME as TRACK_FIRST
from bench.vocabulary import EQUAL_COUNT as EQUAL_KIND
from bench.vocabulary import METHODS, SETTINGS, Method, declare_kind, declare_method

EQUAL_COUNT = declare_kind(
    EQUAL_KIND,
    "a per-view policy run at a peer's own keypoint count in each view (`<policy>@<peer>`)",
    budget="the budget of the peer it is paired with: each view keeps the peer's own count in "
    "that view (more than B where the peer holds more)",
)
EQUAL_PEERS = ("colmap-soft-b",)
"""The peers that hold more keypoints than B (the rest hold exactly B or fewer)."""
EQUAL_POLICIES = ("response", "adaptive-fast", "cross-view", TRACK_FIRST)
"""The policies run at each peer's count: any declared per-view policy, and a multi-view
one that takes a budget per view (`bench.frontend.selection.BY_VIEW`)."""
EQUAL: dict[str, tuple[str, str]] = {}
"""(policy, peer) of each equal-count method, by name."""


def equal_name(policy: str, peer: str) -> str:
    """The name of `policy` at `peer`'s count (`bench.vocabulary.equal_parts`'s inverse)."""
    return f"{policy}@{peer}"


def peer_counts(
    image_dir: Path,
    names: list[str],
    cams: list[Camera],
    peer: str,
    budget: int,
    cache_dir: Path | None = None,
):
    """The number of keypoints the peer's extraction holds in each view at `budget` (the
    peer's own, `bench.backend.peers.peer_extraction`, read from its cache in `cache_dir`)."""
    return [
        len(e.keypoints) for e in peer_extraction(image_dir, names, cams, peer, budget, cache_dir)
    ]


def declare_equal(policy: str, peer: str) -> str:
    """Declare `<policy>@<peer>` (module docstring)."""
    base, name = METHODS[policy], equal_name(policy, peer)
    method = Method(
        name,
        f"{base.label} at {peer}'s count",
        "peer",
        reads=base.reads,
        pool=base.pool,
        kind=EQUAL_COUNT,
        matcher=base.matcher,
    )
    declare_method(method, settings=SETTINGS.get(policy))
    EQUAL[name] = (policy, peer)
    return name


for _peer in EQUAL_PEERS:
    for _policy in EQUAL_POLICIES:
        declare_equal(_policy, _peer)
