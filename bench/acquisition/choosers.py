"""View choosers: which candidate pose of the planned capture path to capture next (the
`nbv` task, `bench.unit.nbv`).

A chooser is one function registered with `@chooser`: it receives a `ChooserInput` (the
captured views with their images, pools, signals and selections, the verified matches,
its own known-pose reconstruction of them, and the candidate poses: cameras without
images) and a seeded generator, and returns the index into `inp.candidates` of the view to
capture next. Every call is checked (`choose`): it returns one integer index of an offered
candidate, or it fails its rows (`ChooserFailed`) and the grid goes on. It runs behind the
ground-truth firewall (`bench.frontend.plugins.firewall`), and this module, like the front
and back end, never imports ground truth (`tests/test_layout.py`).

The pose distance of two cameras a and b (farthest-view, gap-view) is
d(a, b) = |C_a - C_b| / L + angle(z_a, z_b) / 30 degrees, with C the camera centres, z the
optical axes and L the capture's spacing: the median distance from each captured camera
centre to the nearest other one (1 where it is 0).

* `random-view`: a uniform draw among the candidates.
* `farthest-view`: the candidate farthest from the captured views, max_c min_s d(c, s).
* `gap-view`: the views of the path (captured and candidates) in path order, a step's
  length d between consecutive ones; a gap is the stretch between two consecutive captured
  views (or a path end and the nearest captured view) that holds candidates. It picks the
  candidate nearest the middle of the longest gap.
* `weak-triangulation` (the paper's section 7): its weak points are the reconstructed points
  whose largest angle between viewing rays is below `WEAK_ANGLE_DEG`, and the selected
  keypoints no point holds (where the feature field is strong, since the policy selected
  them, but nothing is triangulated): a keypoint with verified matches is placed where
  the rays of its match component meet (least squares, the rig's poses; its observers are
  the views of the component), one without at the median depth of the `NEIGHBOURS` nearest
  triangulated keypoints of its view. A candidate sees a weak point X when X projects into
  its image in front of it, its distance to X is within a factor `SCALE_RATIO` of the
  nearest observer's, and its ray to X is within `MATCHABLE_DEG` of some observer's (else
  it is not expected to match); the angle it gives X is the largest between its ray and
  such an observer's. It picks the candidate with the largest expected gain in capped
  triangulation angle over the weak points it sees: min(max(a0, a), `WEAK_ANGLE_DEG`)
  minus, for a point, min(a0, `WEAK_ANGLE_DEG`), with a0 the point's (or the untriangulated
  track's) largest angle so far and a the candidate's; an untriangulated track counts only
  where the new view brings it to the fewest views the track protocol triangulates
  (`ChooserInput.min_views`: a track matched in two views, under the headline protocol).
  Where no candidate gains anything, it picks as farthest-view. Occlusion is not modelled.

Ties go to the candidate earliest on the path.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from bench import BenchError, MethodFailed
from bench.backend.matching import PairMatches
from bench.camera import Camera
from bench.frontend.features import Candidates
from bench.frontend.plugins import firewall
from bench.frontend.policies import code_line
from bench.frontend.signals import Signals
from bench.frontend.views import View
from bench.vocabulary import Method, declare_kind, declare_method

CHOOSER = declare_kind(
    "view-chooser",
    "chooses the next view to capture from the captured views, their selections, matches "
    "and its own reconstruction and the candidate poses (`@chooser`: the nbv task)",
    budget="the keypoints each captured view keeps: B, selected by the task's policy (nbv.policy)",
)


@dataclass(frozen=True)
class CapturedView:
    """A view captured so far, as the nbv task's keypoint policy saw and selected it."""

    view: View
    """The image: `index` (its position on the path), `name`, `image`, `camera` (the
    intrinsics and the rig pose of the planned path)."""
    candidates: Candidates
    """The view's candidate pool."""
    signals: Signals
    """The signals of the pool (computed over the captured views alone)."""
    selection: np.ndarray
    """Indices into `candidates` of the keypoints the policy selected, ascending."""

    @property
    def keypoints(self) -> np.ndarray:
        """(B, 2) the selected keypoints' pixels; row k is selection k."""
        return self.candidates.xy[self.selection]


@dataclass(frozen=True)
class CandidatePose:
    """A pose of the planned path not captured yet: its camera, never its image."""

    index: int
    """Its position on the path."""
    camera: Camera


@dataclass(frozen=True)
class OwnModel:
    """The chooser's own reconstruction: the selected keypoints triangulated with the rig's
    poses from their verified matches (the `tri` task's, under the run's track protocol)."""

    points: np.ndarray
    """(M, 3) world positions."""
    tracks: tuple[np.ndarray, ...]
    """Per point (K, 2) int rows (captured view, keypoint index into its selection)."""


@dataclass(frozen=True)
class ChooserInput:
    """Everything a chooser may look at: no ground truth, no candidate's image."""

    captured: tuple[CapturedView, ...]
    """The views captured so far, in path order."""
    pairs: tuple[PairMatches, ...]
    """Every pair (i < j, indices into `captured`) with its verified matches (rows of
    keypoint indices into the two selections)."""
    model: OwnModel
    candidates: tuple[CandidatePose, ...]
    """The poses not captured yet, in path order."""
    min_views: int = 3
    """The fewest views a track needs to become a point (the run's track protocol: 3 for
    `multiview`, 2 for `twoview`)."""


Chooser = Callable[[ChooserInput, np.random.Generator], int]
CHOOSERS: dict[str, Chooser] = {}


def chooser(name: str, label: str, role: str = "contender") -> Callable[[Chooser], Chooser]:
    """Register a view chooser under a name no other method has (kind `CHOOSER`; the role
    decides its comparisons in Table 3: each chooser against every baseline)."""

    def register(fn: Chooser) -> Chooser:
        declare_method(Method(name, label, role, kind=CHOOSER))
        CHOOSERS[name] = fn
        return fn

    return register


class ChooserFailed(MethodFailed):
    """A view chooser failed (`MethodFailed`): its rows fail, the grid goes on."""

    def __init__(self, name: str, what: str, where: str):
        super().__init__(name, what, where, f"view chooser {name} {what} (at {where})")


def chooser_rng(seed: int, name: str, step: int) -> np.random.Generator:
    """The generator of one choice: the scene's seed, the chooser and how many views were
    added before it (the same at every budget)."""
    return np.random.default_rng([seed, zlib.crc32(name.encode()), step])


def choose(name: str, inp: ChooserInput, rng: np.random.Generator) -> int:
    """Run a chooser behind the firewall and check its answer: the index of an offered
    candidate (module docstring)."""
    fn = CHOOSERS[name]
    try:
        with firewall():
            out = fn(inp, rng)
    except BenchError:
        raise
    except (Exception, SystemExit) as e:  # a chooser ends no run
        raise ChooserFailed(name, f"failed: {type(e).__name__}: {e}", code_line(fn, e)) from e
    offered = len(inp.candidates)
    if isinstance(out, bool) or not isinstance(out, int | np.integer) or not 0 <= out < offered:
        raise ChooserFailed(
            name,
            f"broke the contract rule 'one offered candidate': returned {out!r} "
            f"({offered} offered)",
            code_line(fn),
        )
    return int(out)


ANGLE_UNIT_DEG = 30.0
"""The viewing-direction change that counts as far as one capture spacing."""


def spacing(cams: list[Camera]) -> float:
    """The median distance from each camera centre to the nearest other one (1 if 0)."""
    C = np.array([c.center for c in cams])
    if len(C) < 2:
        return 1.0
    d = np.linalg.norm(C[:, None] - C[None], axis=2)
    np.fill_diagonal(d, np.inf)
    s = float(np.median(d.min(1)))
    return s if s > 0 else 1.0


def pose_distance(a: Camera, b: Camera, scale: float) -> float:
    """d(a, b) of the module docstring."""
    angle = np.degrees(np.arccos(np.clip(a.R[2] @ b.R[2], -1, 1)))
    return float(np.linalg.norm(a.center - b.center) / scale + angle / ANGLE_UNIT_DEG)


@chooser("random-view", "Random next view", role="baseline")
def random_view(inp: ChooserInput, rng: np.random.Generator) -> int:
    """A uniform draw among the candidates."""
    return int(rng.integers(len(inp.candidates)))


@chooser("farthest-view", "Farthest next view", role="baseline")
def farthest_view(inp: ChooserInput, rng: np.random.Generator) -> int:
    """The candidate whose nearest captured view is farthest (position and direction)."""
    cams = [c.view.camera for c in inp.captured]
    scale = spacing(cams)
    far = [min(pose_distance(c.camera, s, scale) for s in cams) for c in inp.candidates]
    return int(np.argmax(far))


@chooser("gap-view", "Largest path gap", role="baseline")
def gap_view(inp: ChooserInput, rng: np.random.Generator) -> int:
    """The candidate nearest the middle of the longest stretch of the path between
    captured views (module docstring)."""
    scale = spacing([c.view.camera for c in inp.captured])
    path = sorted(
        [(c.view.index, c.view.camera, -1) for c in inp.captured]
        + [(c.index, c.camera, k) for k, c in enumerate(inp.candidates)],
        key=lambda p: p[0],
    )
    steps = [pose_distance(a[1], b[1], scale) for a, b in zip(path, path[1:])]
    arc = np.concatenate([[0.0], np.cumsum(steps)])
    ends = [0] + [k for k, p in enumerate(path) if p[2] < 0] + [len(path) - 1]
    best, pick = -1.0, 0
    for a, b in zip(ends, ends[1:]):
        inside = [k for k in range(a, b + 1) if path[k][2] >= 0]
        if inside and arc[b] - arc[a] > best:
            middle = (arc[a] + arc[b]) / 2
            best = arc[b] - arc[a]
            pick = path[min(inside, key=lambda k: (abs(arc[k] - middle), k))][2]
    return pick


WEAK_ANGLE_DEG = 10.0
"""A point triangulated at a smaller largest angle is weak; the angle at which a point's
gain is capped (where the parallax signal saturates, `bench.frontend.signals`)."""
MATCHABLE_DEG = 40.0
"""A candidate whose ray to a point differs from every observer's by more is not expected
to match it."""
SCALE_RATIO = 2.0
"""A candidate farther from a point, or nearer, than this factor times its nearest
observer is not expected to match it."""
NEIGHBOURS = 8
"""The triangulated keypoints of a view whose median depth places an unmatched keypoint."""
PARALLEL_DEG = 0.5
"""Rays of a match component meeting at a smaller largest angle do not place it."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _largest_angle(X: np.ndarray, centres: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Per point (P, 3) the largest angle in degrees between the rays to it from the
    centres (n, 3) that see it (`seen`: (P, n)); 0 with fewer than two."""
    rays = _unit(centres[None] - X[:, None])  # (P, n, 3)
    cos = np.einsum("pik,pjk->pij", rays, rays)
    both = seen[:, :, None] & seen[:, None, :]
    return np.degrees(np.arccos(np.clip(np.where(both, cos, 1.0).min((1, 2)), -1, 1)))


def _depths(inp: ChooserInput, held: np.ndarray) -> np.ndarray:
    """The depth of every selected keypoint (views in order; `held`: the point holding
    each, `point_of`): its point's for a triangulated one, else the median of its view's
    `NEIGHBOURS` nearest triangulated keypoints' (of every point in front of the view where
    the view has none; NaN where there is no point)."""
    offsets = np.cumsum([0] + [len(c.selection) for c in inp.captured])
    out = []
    for v, cap in enumerate(inp.captured):
        point = held[offsets[v] : offsets[v + 1]]
        cam, own = cap.view.camera, point >= 0
        z = np.full(len(point), np.nan)
        z[own] = cam.to_camera(inp.model.points[point[own]])[:, 2]
        if own.any() and (~own).any():
            k = min(NEIGHBOURS, int(own.sum()))
            _, nn = cKDTree(cap.keypoints[own]).query(cap.keypoints[~own], k=k)
            z[~own] = np.median(z[own][np.asarray(nn).reshape(-1, k)], axis=1)
        elif not own.any() and len(inp.model.points):
            front = cam.to_camera(inp.model.points)[:, 2]
            z[:] = np.median(front[front > 0]) if (front > 0).any() else np.nan
        out.append(z)
    return np.concatenate(out) if out else np.zeros(0)


def point_of(inp: ChooserInput) -> np.ndarray:
    """For every selected keypoint (views in order) the model point holding it, else -1."""
    offsets = np.cumsum([0] + [len(c.selection) for c in inp.captured])
    where = np.full(offsets[-1], -1)
    for p, track in enumerate(inp.model.tracks):
        where[offsets[track[:, 0]] + track[:, 1]] = p
    return where


@dataclass(frozen=True)
class WeakPoints:
    """The weak points of a capture (module docstring)."""

    X: np.ndarray
    """(P, 3) positions."""
    seen: np.ndarray
    """(P, captured) whether each captured view observes each."""
    angle: np.ndarray
    """(P,) the largest angle in degrees between their observers' rays (0 for one)."""
    point: np.ndarray
    """(P,) whether it is a reconstructed point (else an untriangulated track)."""


def weak_points(inp: ChooserInput) -> WeakPoints:
    """The weak points of the module docstring."""
    centres = np.array([c.view.camera.center for c in inp.captured]).reshape(-1, 3)
    n = len(centres)
    X = inp.model.points.reshape(-1, 3)
    seen = np.zeros((len(X), n), bool)
    for p, track in enumerate(inp.model.tracks):
        seen[p, track[:, 0]] = True
    angle = _largest_angle(X, centres, seen)
    weak = angle < WEAK_ANGLE_DEG
    held = point_of(inp)
    depth = _depths(inp, held)
    offsets = np.cumsum([0] + [len(c.selection) for c in inp.captured])
    total, view_of = offsets[-1], np.repeat(np.arange(n), np.diff(offsets))
    rays = np.concatenate([c.view.camera.rays(c.keypoints) for c in inp.captured])
    matched = [p for p in inp.pairs if len(p.verified)]
    r = np.concatenate([offsets[p.i] + p.verified[:, 0] for p in matched] or [np.zeros(0, int)])
    c = np.concatenate([offsets[p.j] + p.verified[:, 1] for p in matched] or [np.zeros(0, int)])
    _, label = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(total, total)))
    components = label.max() + 1 if total else 0
    taken = np.zeros(components, bool)
    taken[label[held >= 0]] = True  # a component a point holds is that point
    free = ~taken[label]
    # where each free component's rays meet (least squares): sum (I - d d^T) (X - C) = 0
    M = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
    A, b = np.zeros((components, 3, 3)), np.zeros((components, 3))
    np.add.at(A, label[free], M[free])
    np.add.at(b, label[free], np.einsum("nij,nj->ni", M[free], centres[view_of[free]]))
    comp_seen = np.zeros((components, n), bool)
    comp_seen[label[free], view_of[free]] = True
    first = np.full(components, total)
    np.minimum.at(first, label[free], np.flatnonzero(free))  # each component's first keypoint
    placed = first < total
    first = np.minimum(first, max(total - 1, 0))
    Xc = centres[view_of[first]] + rays[first] * depth[first][:, None] if total else A[:, 0]
    multi = placed & (comp_seen.sum(1) >= 2) & (np.abs(np.linalg.det(A)) > 1e-9)
    if multi.any():
        met = np.linalg.solve(A[multi], b[multi][..., None])[..., 0]
        wide = _largest_angle(met, centres, comp_seen[multi]) >= PARALLEL_DEG
        Xc[np.flatnonzero(multi)[wide]] = met[wide]
    use = placed & np.isfinite(Xc).all(1)
    Xc, comp_seen = Xc[use], comp_seen[use]
    return WeakPoints(
        np.concatenate([X[weak], Xc]),
        np.concatenate([seen[weak], comp_seen]),
        np.concatenate([angle[weak], _largest_angle(Xc, centres, comp_seen)]),
        np.r_[np.ones(int(weak.sum()), bool), np.zeros(len(Xc), bool)],
    )


def expected_angles(X: np.ndarray, seen: np.ndarray, inp: ChooserInput) -> np.ndarray:
    """(candidates, P): the triangulation angle in degrees each candidate gives each point
    (module docstring), NaN where it does not see it."""
    centres = np.array([c.view.camera.center for c in inp.captured]).reshape(-1, 3)
    to_obs = centres[None] - X[:, None]  # (P, n, 3)
    near = np.where(seen, np.linalg.norm(to_obs, axis=2), np.inf).min(1)
    out = np.full((len(inp.candidates), len(X)), np.nan)
    for k, cand in enumerate(inp.candidates):
        cam = cand.camera
        uv, z = cam.project(X)
        inside = (z > 0) & np.isfinite(uv).all(1)
        inside &= (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0)
        inside &= uv[:, 1] < cam.height
        ray = cam.center - X
        dist = np.linalg.norm(ray, axis=1)
        inside &= (dist <= SCALE_RATIO * near) & (dist * SCALE_RATIO >= near)
        cos = np.einsum("pnk,pk->pn", _unit(to_obs), _unit(ray))
        angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        usable = seen & (angle <= MATCHABLE_DEG)
        best = np.where(usable, angle, -1.0).max(1) if len(X) else np.zeros(0)
        out[k] = np.where(inside & (best >= 0), best, np.nan)
    return out


def angle_gains(weak: WeakPoints, inp: ChooserInput) -> np.ndarray:
    """(candidates, P): each candidate's gain in each weak point's capped triangulation
    angle (module docstring), 0 where it sees it not or brings no point."""
    a = expected_angles(weak.X, weak.seen, inp)
    reach = weak.point | (weak.seen.sum(1) + 1 >= inp.min_views)
    new = np.minimum(np.fmax(weak.angle, a), WEAK_ANGLE_DEG)
    old = np.where(weak.point, np.minimum(weak.angle, WEAK_ANGLE_DEG), 0.0)
    return np.where(np.isfinite(a) & reach, new - old, 0.0)


@chooser("weak-triangulation", "Weak triangulation (paper, section 7)")
def weak_triangulation(inp: ChooserInput, rng: np.random.Generator) -> int:
    """The candidate with the largest expected gain in the weak points' capped
    triangulation angles (module docstring)."""
    score = angle_gains(weak_points(inp), inp).sum(1)
    if not (score > 0).any():
        return farthest_view(inp, rng)
    return int(np.argmax(score))
