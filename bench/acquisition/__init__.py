"""Active acquisition: which view to capture next (the `nbv` task). In: the views
captured so far (images, calibration and rig poses of the planned capture path), each
one's candidate pool, signals and selection, the verified matches, the known-pose
reconstruction made from them, and the candidate poses of the path (poses and
intrinsics, never an image). Out: the candidate to capture next.

`choosers` holds the view choosers (a new chooser goes there). Like the front and back
end, it never sees ground truth (`tests/test_layout.py`).
"""
