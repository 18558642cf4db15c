"""The view oracle of the `nbv` task: the candidate whose addition scores best against the
ground truth, a reference on the evaluation side (greedy: one view at a time), never a
chooser. The front end, back end and choosers cannot import it (`tests/test_layout.py`).

Its score of a capture is the nbv task's (`bench.unit.nbv`): the tri task's
completeness against the path's reconstructable points where there is per-pixel truth,
else the sfm task's mAA over the captured views (a dataset's poses are its truth). At one
view added it is the best candidate by that score, so it bounds every chooser there;
beyond, greedy choices need not be the best set.
"""

from __future__ import annotations

from collections.abc import Callable

from bench.vocabulary import Method, declare_kind, declare_method

VIEW_ORACLE = declare_kind(
    "view-oracle",
    "chooses the next view by its score against the ground truth: a reference of the "
    "evaluation side, never a chooser (the nbv task)",
    budget="the keypoints each captured view keeps: B, selected by the task's policy (nbv.policy)",
)


def best_candidate(offered: list[int], score: Callable[[int], float]) -> int:
    """The offered candidate (path positions) whose capture scores best; ties go to the
    one earliest on the path."""
    return max(sorted(offered), key=lambda c: (score(c), -c))


declare_method(
    Method(
        "oracle-view", "Oracle next view (ground truth, reference)", "reference", kind=VIEW_ORACLE
    )
)
