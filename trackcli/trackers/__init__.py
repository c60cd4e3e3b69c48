"""Trackers: filter steps, and the trackers built on them.

- :mod:`.kalman` — the Kalman filter for AR(2) dynamics: predict and assimilate
  (AC Fig 10.3), steady states, validation gates.
- :mod:`.condensation` — CONDENSATION's sample sets: select, predict, weight (AC Fig 12.6),
  resampling schemes, initial sets.
- :mod:`.tracking` — the frame loops of the Kalman contour tracker and of CONDENSATION,
  each a generator of per-frame results.
- :mod:`.smoothing` — Rauch–Tung–Striebel smoothing of a Kalman track and
  forward-filtering backward-smoothing of a particle track.
"""
