"""Trackers: sample-set steps, and the trackers built on them.

The Kalman filter's steps and the RTS smoother are in :mod:`trackcli.dynamics.kalman` and
:mod:`trackcli.dynamics.rts`, where learning uses them too.

- :mod:`.condensation` — CONDENSATION's sample sets: select (:func:`.condensation.resample`),
  predict, weight (:func:`.condensation.weigh`), one step of AC Fig 12.6 (:func:`.condensation.step`),
  resampling schemes, initial sets.
- :mod:`.base` — the tracker interface (:class:`.base.Tracker`: one frame in, one
  :class:`.base.FrameResult` out; what it supports declared on its class) and the one frame
  loop, :func:`.base.run_tracker`.
- :mod:`.kalman_tracker` — the Kalman contour tracker (AC ch. 10) on that interface.
- :mod:`.coupled` — coupled structures (003): a centre and rays to parts matched by NCC.
- :mod:`.condensation_tracker` — CONDENSATION over curve shape (AC ch. 12) on that interface:
  initial sets, jumps in the motion prior, re-acquisition after loss.
- :mod:`.modes` and :mod:`.mht` — mode-based multiple hypotheses (Cham & Rehg 1999): a few
  Gaussian modes, seeds from the prior refined by Gauss–Newton steps, merged and weighted.
- :mod:`.smoothing` — smoothing a track as it is made: Rauch–Tung–Striebel over a Kalman
  track and forward-filtering backward-smoothing of a particle track.
"""

from __future__ import annotations

from typing import Any

#: the trackers by name (``trackcli track --tracker NAME``): ``module:class`` of a
#: :class:`trackcli.trackers.base.Tracker`, imported when first used
TRACKERS: dict[str, str] = {
    "condensation": "trackcli.trackers.condensation_tracker:CondensationTracker",
    "kalman": "trackcli.trackers.kalman_tracker:KalmanTracker",
    "mht": "trackcli.trackers.mht:MHTTracker",
    "coupled": "trackcli.trackers.coupled:CoupledTracker",
}


def trackers_that(declared: str) -> list[str]:
    """The names of the trackers whose class declares ``declared`` true (e.g. ``"mixed_dynamics"``)."""
    return [name for name in TRACKERS if getattr(tracker_class(name), declared)]


def tracker_class(name: str) -> Any:
    """The :class:`~trackcli.trackers.base.Tracker` subclass called ``name``."""
    from trackcli.registry import lookup

    return lookup(TRACKERS, name, "tracker")
