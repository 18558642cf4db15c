"""The reconstruction back end (COLMAP). In: per view the selected keypoints,
their descriptors and the calibration (never ground truth). Out: tentative and verified
matches per pair and a COLMAP model, or the reason there is none.

`matching` matches and verifies pairs; `reconstruction` builds the COLMAP database and
reconstructs (a new reconstruction task goes there).
"""
