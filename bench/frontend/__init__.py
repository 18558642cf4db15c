"""The front end: what a real front end sees, and the feature policies.
In: a render entry's images and calibration (never its ground truth). Out: per view a
candidate pool with five quality signals, and each policy's selection of B candidates.

`views` loads images and calibration, `features` detects candidates (and holds the
descriptor distance the back end shares), `signals` scores them, `policies` selects (a
new policy goes there), `stage` is the cached front-end stage over a whole entry.
"""
